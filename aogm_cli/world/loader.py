"""Reads a world YAML file into a validated ``World``: the one place world input is checked. Every
error names the file and the key path (``walls[2].thickness``), what was found and what was expected;
the format is documented in ``worlds/README.md``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from aogm_cli.core.errors import InputError
from aogm_cli.io.yamlfile import read_yaml
from aogm_cli.world.config import (
    BlockedCheck,
    Box,
    Circle,
    EchoStrength,
    Firing,
    Floorplan,
    Odometry,
    Opening,
    PassableCheck,
    Polygon,
    Robot,
    SideLobes,
    SimulationErrors,
    Sonar,
    Surface,
    Trajectory,
    Wall,
    World,
)

ROUGH = Surface("rough", math.pi / 2)
# Every number of a world (metres, seconds, degrees) is at most this in magnitude, and the truth
# grid is at least MIN_TRUTH_RESOLUTION fine: cell indexes of every shape then fit in int64 (a
# polygon at 1e300 m made the truth raster's kernel write out of bounds: a segfault).
MAX_MAGNITUDE = 1e6
MIN_TRUTH_RESOLUTION = 1e-4
MAX_SONARS = 100_000  # sonar.count; larger work sizes are refused by world.simulation_cost
MAX_FIRING_INTERVAL = 10.0  # s between a ring's firing slots (errors.firing.interval)
MAX_SCANS = 10_000_000  # scans a waypoint trajectory makes (make bench-scale's largest office: 200,000)
MAX_SUB_RAYS = 1000  # sonar.sub_rays per cone (the default 11)
MAX_TRUTH_RESOLUTION = 1.0  # m per truth cell: coarser holds no wall (walls are 0.1 m thick)


class Node:
    """A YAML value with its key path, so that every complaint can say where it is."""

    def __init__(self, value: Any, path: str, file: str):
        self.value = value
        self.path = path
        self.file = file

    def error(self, message: str) -> InputError:
        return InputError(message, file=self.file, key=self.path or "(top level)")

    def child(self, key: str | int) -> Node:
        if isinstance(key, int):
            path = f"{self.path}[{key}]"
            return Node(self.value[key], path, self.file)
        path = f"{self.path}.{key}" if self.path else key
        return Node(self.value.get(key), path, self.file)

    # -- shapes -------------------------------------------------------------------------
    def mapping(self, allowed: set[str], required: set[str] = frozenset()) -> Node:
        if not isinstance(self.value, dict):
            raise self.error(f"expected a mapping, got {_describe(self.value)}")
        for key in self.value:
            if key not in allowed:
                hint = _closest(str(key), allowed)
                where = f"{self.path}.{key}" if self.path else str(key)
                raise InputError(
                    f"unknown key{hint}; expected one of {', '.join(sorted(allowed))}",
                    file=self.file,
                    key=where,
                )
        for key in sorted(required):
            if key not in self.value:
                raise self.child(key).error("missing; this key is required")
        return self

    def has(self, key: str) -> bool:
        return isinstance(self.value, dict) and key in self.value and self.value[key] is not None

    def items(self) -> list[Node]:
        if not isinstance(self.value, list):
            raise self.error(f"expected a list, got {_describe(self.value)}")
        return [self.child(i) for i in range(len(self.value))]

    # -- scalars ------------------------------------------------------------------------
    def number(self, *, positive: bool = False, minimum: float | None = None, maximum: float | None = None) -> float:
        v = self.value
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise self.error(f"expected a number, got {_describe(v)}")
        v = float(v)
        if abs(v) > MAX_MAGNITUDE:
            raise self.error(f"expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {v:g}")
        if positive and not v > 0:
            raise self.error(f"expected a positive number, got {v:g}")
        if minimum is not None and v < minimum:
            raise self.error(f"expected a number >= {minimum:g}, got {v:g}")
        if maximum is not None and v > maximum:
            raise self.error(f"expected a number <= {maximum:g}, got {v:g}")
        return v

    def integer(self, *, minimum: int | None = None, maximum: int | None = None) -> int:
        v = self.value
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.error(f"expected a whole number, got {_describe(v)}")
        if minimum is not None and v < minimum:
            raise self.error(f"expected a whole number >= {minimum}, got {v}")
        if maximum is not None and v > maximum:
            raise self.error(f"expected a whole number <= {maximum}, got {v}")
        return int(v)

    def string(self) -> str:
        if not isinstance(self.value, str) or not self.value:
            raise self.error(f"expected a non-empty string, got {_describe(self.value)}")
        return self.value

    def vector(self, n: int, what: str = "[x, y]") -> tuple[float, ...]:
        v = self.value
        if not isinstance(v, list) or len(v) != n:
            raise self.error(f"expected {what}, got {_describe(v)}")
        return tuple(self.child(i).number() for i in range(n))

    def points(self, minimum: int) -> tuple[tuple[float, float], ...]:
        pts = tuple(p.vector(2) for p in self.items())
        if len(pts) < minimum:
            raise self.error(f"expected at least {minimum} points [x, y], got {len(pts)}")
        return pts  # type: ignore[return-value]

    # -- helpers with defaults ------------------------------------------------------------
    def get_number(self, key: str, default: float, **limits) -> float:
        return self.child(key).number(**limits) if self.has(key) else default

    def get_angle(self, key: str, default: float, **limits) -> float:
        """An angle written in degrees under ``key``; returned in radians."""
        return math.radians(self.child(key).number(**limits)) if self.has(key) else default


def _describe(v: Any) -> str:
    if v is None:
        return "nothing"
    if isinstance(v, bool):
        return f"the boolean {v}"
    if isinstance(v, (int, float)):
        return f"{v!r}"
    if isinstance(v, str):
        return f"the string {v!r}"
    if isinstance(v, list):
        return f"a list of {len(v)}"
    if isinstance(v, dict):
        return "a mapping"
    return type(v).__name__


def _closest(key: str, allowed: set[str]) -> str:
    import difflib

    match = difflib.get_close_matches(key, sorted(allowed), n=1)
    return f" (did you mean {match[0]!r}?)" if match else ""


TOP_KEYS = {
    "name", "description", "bounds", "truth_resolution", "surfaces", "default_surface", "walls",
    "boxes", "polygons", "circles", "floorplan", "robot", "trajectory", "sonar", "errors", "checks",
}


def load_world(path: str | Path) -> World:
    """Read and validate the world file at ``path``; raise InputError naming file and key."""
    path = Path(path)
    text, raw = read_yaml(path)
    return parse_world(raw, file=str(path), text=text, base_dir=path.parent)


def parse_world(raw: Any, *, file: str, text: str = "", base_dir: Path = Path(".")) -> World:
    """Validate an already-parsed YAML value as a world."""
    top = Node(raw, "", file).mapping(TOP_KEYS, required={"bounds", "trajectory"})

    name = top.child("name").string() if top.has("name") else Path(file).stem
    description = top.child("description").string() if top.has("description") else ""
    bounds = _bounds(top.child("bounds"))
    truth_resolution = _truth_resolution(top, bounds)
    surfaces = _surfaces(top)
    walls = _walls(top, surfaces) if top.has("walls") else []
    boxes = _boxes(top, surfaces) if top.has("boxes") else []
    polygons = _polygons(top, surfaces) if top.has("polygons") else []
    circles = _circles(top, surfaces) if top.has("circles") else []
    floorplan = _floorplan(top.child("floorplan"), surfaces, base_dir) if top.has("floorplan") else None
    robot = _robot(top.child("robot")) if top.has("robot") else Robot()
    trajectory = _trajectory(top.child("trajectory"), bounds)
    sonar = _sonar(top.child("sonar") if top.has("sonar") else Node({}, "sonar", file), robot)
    errors = _errors(top.child("errors") if top.has("errors") else Node({}, "errors", file), sonar)
    checks = _checks(top.child("checks"), bounds, robot) if top.has("checks") else []

    if not (walls or boxes or polygons or circles or floorplan):
        raise top.error("the world has no geometry; expected walls, boxes, polygons, circles or a floorplan")

    return World(
        name=name,
        source=file,
        text=text,
        bounds=bounds,
        truth_resolution=truth_resolution,
        surfaces=surfaces.by_name,
        walls=tuple(walls),
        boxes=tuple(boxes),
        polygons=tuple(polygons),
        circles=tuple(circles),
        floorplan=floorplan,
        robot=robot,
        trajectory=trajectory,
        sonar=sonar,
        errors=errors,
        checks=tuple(checks),
        description=description,
    )


# -- sections of the world, in the order they are checked ----------------------------------


def _bounds(n: Node) -> tuple[float, float, float, float]:
    b = n.vector(4, "[x_min, y_min, x_max, y_max]")
    if not (b[2] > b[0] and b[3] > b[1]):
        raise n.error(f"expected x_max > x_min and y_max > y_min, got {list(b)}")
    return (b[0], b[1], b[2], b[3])


def _truth_resolution(top: Node, bounds: tuple[float, float, float, float]) -> float:
    truth_resolution = top.get_number("truth_resolution", 0.05, minimum=MIN_TRUTH_RESOLUTION,
                                      maximum=MAX_TRUTH_RESOLUTION)
    if (bounds[2] - bounds[0]) * (bounds[3] - bounds[1]) / truth_resolution**2 > 2.5e8:
        raise top.child("truth_resolution").error("the truth grid would exceed 250 million cells; expected a coarser resolution")
    return truth_resolution


class Surfaces:
    """The world's surfaces by name (always "rough") and the one a solid without ``surface`` gets."""

    def __init__(self, by_name: dict[str, Surface], default: str):
        self.by_name = by_name
        self.default = default

    def of(self, n: Node) -> str:
        """The surface named under ``n.surface``, checked, or the default."""
        if not n.has("surface"):
            return self.default
        s = n.child("surface").string()
        if s not in self.by_name:
            raise n.child("surface").error(f"unknown surface {s!r}; expected one of {sorted(self.by_name)}")
        return s


def _surfaces(top: Node) -> Surfaces:
    surfaces = {"rough": ROUGH}
    if top.has("surfaces"):
        s_node = top.child("surfaces")
        if not isinstance(s_node.value, dict):
            raise s_node.error(f"expected a mapping of surface names, got {_describe(s_node.value)}")
        for sname in s_node.value:
            n = s_node.child(sname).mapping({"specular_threshold_deg"}, required={"specular_threshold_deg"})
            th = n.child("specular_threshold_deg").number(minimum=0.0, maximum=90.0)
            surfaces[str(sname)] = Surface(str(sname), math.radians(th))
    default_surface = top.child("default_surface").string() if top.has("default_surface") else "rough"
    if default_surface not in surfaces:
        raise top.child("default_surface").error(f"unknown surface {default_surface!r}; expected one of {sorted(surfaces)}")
    return Surfaces(surfaces, default_surface)


def _walls(top: Node, surfaces: Surfaces) -> list[Wall]:
    walls = []
    for w in top.child("walls").items():
        w.mapping({"points", "thickness", "surface", "openings"}, required={"points"})
        pts = w.child("points").points(2)
        thickness = w.get_number("thickness", 0.1, positive=True)
        length = sum(math.dist(pts[i], pts[i + 1]) for i in range(len(pts) - 1))
        openings = []
        if w.has("openings"):
            for o in w.child("openings").items():
                o.mapping({"at", "width"}, required={"at", "width"})
                at = o.child("at").number(minimum=0.0, maximum=length)
                width = o.child("width").number(positive=True)
                openings.append(Opening(at, width))
        walls.append(Wall(pts, thickness, surfaces.of(w), tuple(openings)))
    return walls


def _boxes(top: Node, surfaces: Surfaces) -> list[Box]:
    boxes = []
    for n in top.child("boxes").items():
        n.mapping({"center", "size", "yaw_deg", "surface"}, required={"center", "size"})
        size = n.child("size").vector(2, "[width, depth]")
        if not (size[0] > 0 and size[1] > 0):
            raise n.child("size").error(f"expected positive [width, depth], got {list(size)}")
        boxes.append(Box(n.child("center").vector(2), size, n.get_angle("yaw_deg", 0.0), surfaces.of(n)))
    return boxes


def _polygons(top: Node, surfaces: Surfaces) -> list[Polygon]:
    polygons = []
    for n in top.child("polygons").items():
        n.mapping({"points", "surface"}, required={"points"})
        polygons.append(Polygon(n.child("points").points(3), surfaces.of(n)))
    return polygons


def _circles(top: Node, surfaces: Surfaces) -> list[Circle]:
    circles = []
    for n in top.child("circles").items():
        n.mapping({"center", "radius", "surface"}, required={"center", "radius"})
        circles.append(Circle(n.child("center").vector(2), n.child("radius").number(positive=True), surfaces.of(n)))
    return circles


def _floorplan(n: Node, surfaces: Surfaces, base_dir: Path) -> Floorplan:
    n.mapping({"map", "surface"}, required={"map"})
    map_path = (base_dir / n.child("map").string()).resolve()
    from aogm_cli.io.map_server import read_map_yaml

    try:
        plan = read_map_yaml(map_path)
    except InputError as exc:
        raise n.child("map").error(f"cannot load the map_server YAML: {exc}") from None
    return Floorplan(str(map_path), surfaces.of(n), plan)


def _robot(n: Node) -> Robot:
    n.mapping({"radius"})
    return Robot(n.get_number("radius", Robot.radius, positive=True))


CHECK_CLASSES = {c.kind: c for c in (PassableCheck, BlockedCheck)}  # a check's key (core.log.CHECK_KINDS)


def _checks(checks: Node, bounds, robot: Robot) -> list[PassableCheck]:
    out = []
    names = set()
    for n in checks.items():
        n.mapping({"name", *CHECK_CLASSES}, required={"name"})
        kinds = [k for k in CHECK_CLASSES if k in n.value]
        if len(kinds) != 1:
            raise n.error(f"expected exactly one of {' or '.join(repr(k) for k in CHECK_CLASSES)} beside 'name'")
        cname = n.child("name").string()
        if cname in names:
            raise n.child("name").error(f"duplicate check name {cname!r}")
        names.add(cname)
        p = n.child(kinds[0]).mapping({"from", "to", "robot_radius"}, required={"from", "to"})
        start = p.child("from").vector(2)
        goal = p.child("to").vector(2)
        for key, pt in (("from", start), ("to", goal)):
            if not _inside(pt, bounds):
                raise p.child(key).error(f"expected a point inside bounds {list(bounds)}, got {list(pt)}")
        radius = p.get_number("robot_radius", robot.radius, minimum=0.0)
        out.append(CHECK_CLASSES[kinds[0]](cname, start, goal, radius))
    return out


def _inside(pt, bounds) -> bool:
    return bounds[0] <= pt[0] <= bounds[2] and bounds[1] <= pt[1] <= bounds[3]


def _trajectory(n: Node, bounds) -> Trajectory:
    n.mapping({"waypoints", "speed", "scan_period", "poses", "turn_rate_deg"})
    scan_period = n.get_number("scan_period", Trajectory.scan_period, positive=True)
    if n.has("poses") == n.has("waypoints"):
        raise n.error("expected exactly one of 'waypoints' (with speed) or 'poses'")
    if n.has("poses") and n.has("turn_rate_deg"):
        raise n.child("turn_rate_deg").error("expected only with 'waypoints' (explicit poses turn as they are written)")
    if n.has("poses"):
        poses = []
        for p in n.child("poses").items():
            x, y, yaw_deg = p.vector(3, "[x, y, yaw_deg]")
            if not _inside((x, y), bounds):
                raise p.error(f"expected a pose inside bounds {list(bounds)}, got [{x:g}, {y:g}]")
            poses.append((x, y, math.radians(yaw_deg)))
        if not poses:
            raise n.child("poses").error("expected at least one pose")
        return Trajectory(poses=tuple(poses), scan_period=scan_period)
    waypoints = n.child("waypoints").points(2)
    for i, pt in enumerate(waypoints):
        if not _inside(pt, bounds):
            raise n.child("waypoints").child(i).error(f"expected a point inside bounds {list(bounds)}, got {list(pt)}")
    if all(math.dist(waypoints[0], p) == 0 for p in waypoints):
        raise n.child("waypoints").error("expected waypoints that span a distance, got one repeated point")
    traj = Trajectory(waypoints=waypoints, speed=n.get_number("speed", Trajectory.speed, positive=True), scan_period=scan_period,
                      turn_rate=n.get_angle("turn_rate_deg", 0.0, positive=True, maximum=3600.0))
    from aogm_cli.world.trajectory import Polyline  # the drive's length and turns, as the simulator drives it

    path = Polyline(waypoints)
    seconds = path.length / traj.speed + (float(abs(path.turns()).sum()) / traj.turn_rate if traj.turn_rate else 0.0)
    if seconds / scan_period > MAX_SCANS:
        raise n.error(f"speed {traj.speed:g} m/s and scan_period {scan_period:g} s make {seconds / scan_period:.3g} "
                      f"scans of the {path.length:g} m drive; expected at most {MAX_SCANS:g} (a faster speed or a "
                      "longer scan_period)")
    return traj


def _sonar(n: Node, robot: Robot) -> Sonar:
    n.mapping({
        "count", "ring_radius", "mounts", "beam_width_deg", "min_range", "max_range", "noise_sigma",
        "random_rate", "sub_rays", "max_bounces", "cause_tolerance",
    })
    if n.has("mounts") and (n.has("count") or n.has("ring_radius")):
        raise n.error("expected either 'mounts' or 'count'/'ring_radius', not both")
    if n.has("mounts"):
        mounts = []
        for m in n.child("mounts").items():
            x, y, yaw_deg = m.vector(3, "[x, y, yaw_deg]")
            mounts.append((x, y, math.radians(yaw_deg)))
        if not mounts:
            raise n.child("mounts").error("expected at least one sonar, got zero")
    else:
        # the mounts are built here: a ring beyond MAX_SONARS is refused before it is built
        count = n.child("count").integer(minimum=1, maximum=MAX_SONARS) if n.has("count") else 24
        ring = n.get_number("ring_radius", robot.radius, minimum=0.0)
        mounts = []
        for i in range(count):
            a = 2.0 * math.pi * i / count
            mounts.append((ring * math.cos(a), ring * math.sin(a), a))
    beam = n.get_angle("beam_width_deg", Sonar.beam_width, positive=True, maximum=179.0)
    min_range = n.get_number("min_range", Sonar.min_range, minimum=0.0)
    max_range = n.get_number("max_range", Sonar.max_range, positive=True)
    if not max_range > min_range:
        raise n.child("max_range").error(f"expected max_range > min_range ({min_range:g}), got {max_range:g}")
    return Sonar(
        mounts=tuple(mounts),
        beam_width=beam,
        min_range=min_range,
        max_range=max_range,
        noise_sigma=n.get_number("noise_sigma", Sonar.noise_sigma, minimum=0.0),
        random_rate=n.get_number("random_rate", Sonar.random_rate, minimum=0.0, maximum=1.0),
        sub_rays=n.child("sub_rays").integer(minimum=1, maximum=MAX_SUB_RAYS) if n.has("sub_rays") else Sonar.sub_rays,
        max_bounces=n.child("max_bounces").integer(minimum=0) if n.has("max_bounces") else Sonar.max_bounces,
        cause_tolerance=n.get_number("cause_tolerance", Sonar.cause_tolerance, positive=True),
    )


def _errors(n: Node, sonar: Sonar) -> SimulationErrors:
    """The ``errors:`` section: every error of a real robot, each off by default."""
    n.mapping({"odometry", "noise_per_metre", "crosstalk_rate", "echo_strength", "firing", "side_lobes"})
    odometry = Odometry()
    if n.has("odometry"):
        o = n.child("odometry").mapping({
            "translation", "rotation", "rotation_per_metre_deg", "heading_bias_per_metre_deg", "turn_bias",
        })
        odometry = Odometry(
            translation=o.get_number("translation", 0.0, minimum=0.0, maximum=1.0),
            rotation=o.get_number("rotation", 0.0, minimum=0.0, maximum=1.0),
            rotation_per_metre=o.get_angle("rotation_per_metre_deg", 0.0, minimum=0.0, maximum=90.0),
            heading_bias_per_metre=o.get_angle("heading_bias_per_metre_deg", 0.0, minimum=-90.0, maximum=90.0),
            turn_bias=o.get_number("turn_bias", 0.0, minimum=-0.5, maximum=0.5),
        )
    e = n.child("echo_strength") if n.has("echo_strength") else Node({}, f"{n.path}.echo_strength", n.file)
    e.mapping({"min_strength", "beam_deg", "incidence_exponent"})
    echo_strength = EchoStrength(
        min_strength=e.get_number("min_strength", 0.0, minimum=0.0),
        beam=e.get_angle("beam_deg", sonar.beam_width / 2, positive=True, maximum=90.0),
        incidence_exponent=e.get_number("incidence_exponent", EchoStrength.incidence_exponent, minimum=0.0, maximum=100.0),
    )
    return SimulationErrors(
        odometry=odometry,
        noise_per_metre=n.get_number("noise_per_metre", 0.0, minimum=0.0, maximum=1.0),
        crosstalk_rate=n.get_number("crosstalk_rate", 0.0, minimum=0.0, maximum=1.0),
        echo_strength=echo_strength,
        firing=_firing(n.child("firing"), sonar) if n.has("firing") else Firing(),
        side_lobes=_side_lobes(n.child("side_lobes")) if n.has("side_lobes") else SideLobes(),
    )


def _firing(n: Node, sonar: Sonar) -> Firing:
    """``errors.firing``: the ring's firing cycle, slot after slot ``interval`` seconds apart."""
    n.mapping({"interval", "slots"})
    slots: tuple[int, ...] = ()
    if n.has("slots"):
        slots = tuple(s.integer(minimum=0, maximum=MAX_SONARS) for s in n.child("slots").items())
        if len(slots) != len(sonar.mounts):
            raise n.child("slots").error(f"expected one slot per sonar ({len(sonar.mounts)}), got {len(slots)}")
    return Firing(n.get_number("interval", 0.0, minimum=0.0, maximum=MAX_FIRING_INTERVAL), slots)


def _side_lobes(n: Node) -> SideLobes:
    """``errors.side_lobes``: a weak lobe either side of the beam that hears near surfaces."""
    n.mapping({"range", "angle_deg", "width_deg", "sub_rays"})
    angle = n.get_angle("angle_deg", SideLobes.angle, positive=True, maximum=90.0)
    width = n.get_angle("width_deg", SideLobes.width, minimum=0.0, maximum=90.0)
    if not width / 2 < angle:
        raise n.child("width_deg").error(
            f"expected a lobe clear of the axis (width_deg < 2 angle_deg = {2 * math.degrees(angle):g}), "
            f"got {math.degrees(width):g}")
    return SideLobes(
        range=n.get_number("range", 0.0, minimum=0.0),
        angle=angle,
        width=width,
        sub_rays=n.child("sub_rays").integer(minimum=1, maximum=100) if n.has("sub_rays") else SideLobes.sub_rays,
    )
