"""A generated office floor for benchmarks at building scale (``office_spec``, ``office_yaml``): a
corridor ring with 40 rooms, doors, glass fronts and furniture, driven in laps with detours into the
rooms; everything from ``seed``, so a shorter run's path is the start of a longer one's."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import yaml

# A 60 m x 40 m floor (1220 x 820 truth cells at 0.05 m with its margin): a 2 m corridor ring with
# 40 rooms around it, 28 in the outer bands (four corner rooms entered from a neighbour through a
# connecting door) and 12 deep rooms in the core. Every room facing the corridor has a door 0.8-1.6 m
# wide; about a third of the fronts are glass; furniture (desks, tables, metal cabinets, chairs, bins)
# is placed clear of the door and of the robot's way in. The robot does laps of the ring, alternately
# counter-clockwise and clockwise and a little off the centre line, with detours through the doors
# into the rooms (every room on the first lap, about half of them on later laps), until it has made
# exactly ``scans`` scans. The floor comes from one random stream, the laps from another, so the same
# seed gives the same floor at any number of scans. The result is the raw mapping of a world file
# (``worlds/README.md``); ``office_yaml`` writes it as YAML and ``world.loader.parse_world`` reads it.
WIDTH, HEIGHT = 60.0, 40.0
BAND = 6.0  # depth of the outer rooms
CORRIDOR = 2.0
RING_OUT = (BAND, BAND, WIDTH - BAND, HEIGHT - BAND)  # the corridor's outer boundary (6, 6, 54, 34)
RING_IN = (BAND + CORRIDOR, BAND + CORRIDOR, WIDTH - BAND - CORRIDOR, HEIGHT - BAND - CORRIDOR)  # (8, 8, 52, 32)
OUTER_ROOMS_X = 10  # rooms along the bottom and the top band (two of each are corner rooms)
OUTER_ROOMS_Y = 4  # rooms along the left and the right band
CORE_ROOMS_X = 6  # rooms in each of the core's two rows
DOOR_WIDTHS = (0.8, 1.6)
GLASS_SHARE = 0.3
ROBOT_RADIUS = 0.25
LANE = 0.3  # largest offset of a lap from the corridor's centre line
SPEED, SCAN_PERIOD = 0.3, 0.5  # the world format's defaults: a scan every 0.15 m
SURFACES = {
    "glass": {"specular_threshold_deg": 15},
    "smooth": {"specular_threshold_deg": 25},  # painted walls, metal cabinets
}


@dataclass(frozen=True)
class Room:
    """A rectangular room; ``front`` is the side its door is on ("S", "N", "W", "E"), and
    ``door`` the door's centre along that side (x for S/N, y for W/E)."""

    x0: float
    y0: float
    x1: float
    y1: float
    front: str
    door: float
    door_width: float
    glass: bool
    corridor: bool  # the door opens onto the corridor (else into a neighbouring room)

    @property
    def depth(self) -> float:
        """How far the room reaches from its front wall."""
        return self.y1 - self.y0 if self.front in "SN" else self.x1 - self.x0

    @property
    def reach(self) -> float:
        """The deepest point of a detour into the room, from its front wall."""
        return min(3.5, self.depth - 1.5)

    def inside(self, depth: float) -> tuple[float, float]:
        """The point ``depth`` into the room on the door's axis."""
        if self.front == "S":
            return (self.door, self.y0 + depth)
        if self.front == "N":
            return (self.door, self.y1 - depth)
        if self.front == "W":
            return (self.x0 + depth, self.door)
        return (self.x1 - depth, self.door)

    def front_wall(self) -> tuple[tuple[float, float], tuple[float, float]]:
        if self.front == "S":
            return (self.x0, self.y0), (self.x1, self.y0)
        if self.front == "N":
            return (self.x0, self.y1), (self.x1, self.y1)
        if self.front == "W":
            return (self.x0, self.y0), (self.x0, self.y1)
        return (self.x1, self.y0), (self.x1, self.y1)


def _door(rng: random.Random, lo: float, hi: float) -> tuple[float, float]:
    """(centre, width) of a door in a wall from ``lo`` to ``hi``, at least 1 m from either end."""
    width = round(rng.uniform(*DOOR_WIDTHS) / 0.05) * 0.05
    margin = 1.0 + width / 2
    return round(rng.uniform(lo + margin, hi - margin), 2), round(width, 2)


def _rooms(rng: random.Random) -> list[Room]:
    """The 40 rooms: bottom and top bands, left and right bands, the core's two rows."""
    rooms = []
    ox0, oy0, ox1, oy1 = RING_OUT
    ix0, iy0, ix1, iy1 = RING_IN
    step = WIDTH / OUTER_ROOMS_X
    for y0, y1, front in ((0.0, oy0, "N"), (oy1, HEIGHT, "S")):
        for i in range(OUTER_ROOMS_X):
            x0, x1 = i * step, (i + 1) * step
            corner = i in (0, OUTER_ROOMS_X - 1)
            if corner:  # a connecting door in the wall shared with the band's next room
                side = "E" if i == 0 else "W"
                at, width = _door(rng, y0, y1)
                rooms.append(Room(x0, y0, x1, y1, side, at, width, False, False))
            else:
                at, width = _door(rng, x0, x1)
                rooms.append(Room(x0, y0, x1, y1, front, at, width, rng.random() < GLASS_SHARE, True))
    step = (oy1 - oy0) / OUTER_ROOMS_Y
    for x0, x1, front in ((0.0, ox0, "E"), (ox1, WIDTH, "W")):
        for j in range(OUTER_ROOMS_Y):
            y0, y1 = oy0 + j * step, oy0 + (j + 1) * step
            at, width = _door(rng, y0, y1)
            rooms.append(Room(x0, y0, x1, y1, front, at, width, rng.random() < GLASS_SHARE, True))
    step = (ix1 - ix0) / CORE_ROOMS_X
    mid = (iy0 + iy1) / 2
    for y0, y1, front in ((iy0, mid, "S"), (mid, iy1, "N")):
        for i in range(CORE_ROOMS_X):
            x0, x1 = round(ix0 + i * step, 3), round(ix0 + (i + 1) * step, 3)
            at, width = _door(rng, x0, x1)
            rooms.append(Room(x0, y0, x1, y1, front, at, width, rng.random() < GLASS_SHARE, True))
    return rooms


def _walls(rooms: list[Room], rng: random.Random) -> list[dict]:
    """The outer wall, each room's front wall with its door, and the walls between rooms."""
    walls = [{"points": [[0, 0], [WIDTH, 0], [WIDTH, HEIGHT], [0, HEIGHT], [0, 0]], "thickness": 0.2}]
    for room in rooms:
        a, b = room.front_wall()
        start = a[0] if room.front in "SN" else a[1]
        wall = {"points": [list(a), list(b)], "openings": [{"at": round(room.door - start, 3), "width": room.door_width}]}
        if room.glass:
            wall["surface"] = "glass"
        walls.append(wall)
    ox0, oy0, ox1, oy1 = RING_OUT
    ix0, iy0, ix1, iy1 = RING_IN
    cuts = []
    step = WIDTH / OUTER_ROOMS_X
    for i in range(2, OUTER_ROOMS_X - 1):  # between the bands' rooms (the corner rooms' walls are fronts)
        cuts += [[[i * step, 0.0], [i * step, oy0]], [[i * step, oy1], [i * step, HEIGHT]]]
    step = (oy1 - oy0) / OUTER_ROOMS_Y
    for j in range(OUTER_ROOMS_Y + 1):
        y = oy0 + j * step
        cuts += [[[0.0, y], [ox0, y]], [[ox1, y], [WIDTH, y]]]
    step = (ix1 - ix0) / CORE_ROOMS_X
    for i in range(1, CORE_ROOMS_X):
        cuts.append([[round(ix0 + i * step, 3), iy0], [round(ix0 + i * step, 3), iy1]])
    cuts.append([[ix0, (iy0 + iy1) / 2], [ix1, (iy0 + iy1) / 2]])
    for points in cuts:
        wall = {"points": points}
        if rng.random() < 0.2:
            wall["surface"] = "smooth"
        walls.append(wall)
    walls.append({"points": [[ix0, iy0], [ix0, iy1]]})  # the core's ends, one of them glass
    walls.append({"points": [[ix1, iy0], [ix1, iy1]], "surface": "glass"})
    return walls


def _furniture(room: Room, rng: random.Random) -> tuple[list[dict], list[dict]]:
    """Boxes and circles placed in ``room``, clear of its walls (0.15 m), of each other (0.3 m)
    and of the robot's way in (the door's width plus the robot's and 0.1 m on either side,
    0.6 m beyond the deepest detour); a corner room only keeps its connecting door clear."""
    boxes: list[dict] = []
    circles: list[dict] = []
    placed: list[tuple[float, float, float]] = []  # bounding circles
    area = (room.x1 - room.x0) * (room.y1 - room.y0)
    kinds = ["desk", "desk", "cabinet", "chair", "chair", "bin"]
    if area > 60:
        kinds += ["table", "chair", "chair", "desk", "cabinet"]
    half = max(room.door_width / 2, 0.6) + ROBOT_RADIUS + 0.1
    depth = (room.reach if room.corridor else 1.0) + 0.6
    for kind in kinds:
        if kind in ("desk", "table", "cabinet"):
            w, d = {"desk": (rng.uniform(1.2, 1.6), rng.uniform(0.6, 0.8)), "table": (rng.uniform(2.4, 3.2), 1.2),
                    "cabinet": (rng.uniform(0.9, 1.8), 0.45)}[kind]
            yaw = rng.choice([0.0, 90.0, rng.uniform(-30.0, 30.0)])
            r = math.hypot(w, d) / 2
        else:
            r = {"chair": rng.uniform(0.22, 0.3), "bin": rng.uniform(0.12, 0.18)}[kind]
        for _ in range(60):
            x = rng.uniform(room.x0 + 0.15 + r, room.x1 - 0.15 - r)
            y = rng.uniform(room.y0 + 0.15 + r, room.y1 - 0.15 - r)
            along, into = (x, abs(y - room.inside(0)[1])) if room.front in "SN" else (y, abs(x - room.inside(0)[0]))
            if abs(along - room.door) < half + r and into < depth + r:
                continue
            if any(math.dist((x, y), (px, py)) < r + pr + 0.3 for px, py, pr in placed):
                continue
            placed.append((x, y, r))
            if kind in ("desk", "table", "cabinet"):
                box = {"center": [round(x, 3), round(y, 3)], "size": [round(w, 3), round(d, 3)], "yaw_deg": round(yaw, 1)}
                if kind == "cabinet":
                    box["surface"] = "smooth"
                boxes.append(box)
            else:
                circles.append({"center": [round(x, 3), round(y, 3)], "radius": round(r, 3)})
            break
    return boxes, circles


def _lap(rooms: list[Room], offset: float, clockwise: bool, detours: dict[int, float]) -> list[tuple[float, float]]:
    """One lap of the ring from its bottom-left corner, ``offset`` inside the centre line, with a
    detour (in along the door's axis to the given depth, and back) into each room of ``detours``."""
    x0, y0, x1, y1 = (c + s * (CORRIDOR / 2 + offset) for c, s in zip(RING_OUT, (1, 1, -1, -1), strict=True))
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
    if clockwise:
        corners.reverse()
    path = [corners[0]]
    for a, b in zip(corners[:-1], corners[1:], strict=True):
        axis = 0 if a[1] == b[1] else 1  # the coordinate that changes along this leg
        lane = a[1 - axis]
        sign = 1.0 if b[axis] > a[axis] else -1.0
        stops = []
        for i, depth in detours.items():
            room = rooms[i]
            if (room.front in "SN") == (axis == 0):
                wall = room.inside(0)[1 - axis]
                if abs(wall - lane) <= CORRIDOR:  # a door onto this leg of the corridor
                    stops.append((sign * room.door, room, depth))
        for _, room, depth in sorted(stops, key=lambda s: s[0]):
            at = (room.door, lane) if axis == 0 else (lane, room.door)
            path += [at, room.inside(depth), at]
        path.append(b)
    return path


def _route(rooms: list[Room], rng: random.Random, length: float) -> list[list[float]]:
    """Laps until the path is ``length`` long, cut there; waypoints rounded to the millimetre."""
    visit = [i for i, r in enumerate(rooms) if r.corridor]
    points: list[tuple[float, float]] = []
    total = 0.0
    lap = 0
    while True:
        offset = 0.0 if lap == 0 else rng.uniform(-LANE, LANE)
        chosen = visit if lap == 0 else [i for i in visit if rng.random() < 0.5]
        detours = {i: rng.uniform(1.5, rooms[i].reach) for i in chosen}
        for p in _lap(rooms, offset, lap % 2 == 1, detours):
            p = (round(p[0], 3), round(p[1], 3))
            if points:
                leg = math.dist(points[-1], p)
                if leg == 0.0:
                    continue
                if total + leg >= length:
                    f = (length - total) / leg
                    last = points[-1]
                    points.append((round(last[0] + f * (p[0] - last[0]), 3), round(last[1] + f * (p[1] - last[1]), 3)))
                    return [list(q) for q in points]
                total += leg
            points.append(p)
        lap += 1


def office_spec(scans: int, seed: int = 1, speed: float = SPEED, scan_period: float = SCAN_PERIOD) -> dict:
    """The office world making exactly ``scans`` scans, as the mapping a world YAML file holds."""
    if scans < 2:
        raise ValueError(f"expected at least 2 scans, got {scans}")
    floor = random.Random(f"office floor {seed}")
    rooms = _rooms(floor)
    walls = _walls(rooms, floor)
    boxes, circles = [], []
    for room in rooms:
        b, c = _furniture(room, floor)
        boxes += b
        circles += c
    step = speed * scan_period
    waypoints = _route(rooms, random.Random(f"office laps {seed}"), (scans - 0.5) * step)
    first = next(r for r in rooms if r.corridor and r.front == "S" and r.y0 == RING_IN[1])  # the core's first room
    widest = max((r for r in rooms if r.corridor), key=lambda r: r.door_width)
    narrowest = min((r for r in rooms if r.corridor), key=lambda r: r.door_width)
    lane = RING_OUT[0] + CORRIDOR / 2

    def door_check(name: str, room: Room) -> dict:
        outside = room.inside(-CORRIDOR / 2)
        return {"name": name, "passable": {"from": [round(v, 3) for v in outside],
                                           "to": [round(v, 3) for v in room.inside(1.2)]}}

    return {
        "name": f"office_{scans}",
        "description": (f"Generated office floor (aogm_cli/world/office.py, seed {seed}): {WIDTH:g} m x {HEIGHT:g} m, "
                        f"{len(rooms)} rooms around a {CORRIDOR:g} m corridor ring, doors "
                        f"{DOOR_WIDTHS[0]:g}-{DOOR_WIDTHS[1]:g} m, glass fronts, furniture; "
                        f"{scans} scans of laps with detours into the rooms."),
        "bounds": [-0.5, -0.5, WIDTH + 0.5, HEIGHT + 0.5],
        "truth_resolution": 0.05,
        "surfaces": SURFACES,
        "walls": walls,
        "boxes": boxes,
        "circles": circles,
        "robot": {"radius": ROBOT_RADIUS},
        "trajectory": {"waypoints": waypoints, "speed": speed, "scan_period": scan_period},
        "sonar": {"count": 24},
        "checks": [
            {"name": "ring_half", "passable": {"from": [lane, lane], "to": [WIDTH - lane, HEIGHT - lane]}},
            door_check("core_door", first),
            door_check("widest_door", widest),
            door_check("narrowest_door", narrowest),
        ],
    }


def office_yaml(spec: dict, comment: str = "") -> str:
    """``spec`` as world YAML: one line per wall, box, circle, waypoint and check."""

    def flow(value) -> str:
        text = yaml.safe_dump(value, default_flow_style=True, width=math.inf, sort_keys=False)
        return text.removesuffix("...\n").strip()  # a scalar's document ends with "..."

    lines = [f"# {line}" for line in comment.splitlines()]
    for key, value in spec.items():
        if key == "trajectory":
            lines += ["trajectory:", f"  speed: {value['speed']!r}", f"  scan_period: {value['scan_period']!r}", "  waypoints:"]
            lines += [f"    - {flow(p)}" for p in value["waypoints"]]
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            lines.append(f"{key}:")
            lines += [f"  - {flow(item)}" for item in value]
        elif isinstance(value, dict):
            lines.append(f"{key}:")
            lines += [f"  {k}: {flow(v)}" for k, v in value.items()]
        elif isinstance(value, list):
            lines.append(f"{key}: {flow(value)}")
        else:
            lines.append(yaml.safe_dump({key: value}, width=math.inf).rstrip())
    return "\n".join(lines) + "\n"
