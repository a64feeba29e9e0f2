"""The world as typed, frozen configuration (geometry, surfaces, robot, trajectory, sonar, a real
robot's errors, checks), as ``world.loader`` produces it from YAML after validation: nothing else reads
world YAML. Angles are in radians, lengths in metres."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from aogm_cli.core.log import SensorSpec

if TYPE_CHECKING:
    from aogm_cli.io.map_server import RosMap  # not at start-up: it loads numpy and Pillow

Point = tuple[float, float]


@dataclass(frozen=True)
class Surface:
    """Reflection property of a surface: echoes come back only below the specular threshold.

    ``specular_threshold`` is the largest incidence angle (from the surface normal) that
    still echoes; pi/2 means a rough surface that echoes at any angle.
    """

    name: str
    specular_threshold: float = math.pi / 2


@dataclass(frozen=True)
class Opening:
    """A gap cut into a wall: centred ``at`` metres along the polyline, ``width`` wide."""

    at: float
    width: float


@dataclass(frozen=True)
class Wall:
    """A polyline wall of a given thickness, with optional openings (doors)."""

    points: tuple[Point, ...]
    thickness: float
    surface: str
    openings: tuple[Opening, ...] = ()


@dataclass(frozen=True)
class Box:
    """A rectangle ``size`` = (width along its x, depth along its y), rotated by ``yaw`` about its centre."""

    center: Point
    size: Point
    yaw: float
    surface: str


@dataclass(frozen=True)
class Polygon:
    """A simple closed polygon (the last point joins the first)."""

    points: tuple[Point, ...]
    surface: str


@dataclass(frozen=True)
class Circle:
    center: Point
    radius: float
    surface: str


@dataclass(frozen=True)
class Floorplan:
    """A bitmap floor plan read as ROS map_server reads ``map`` (a map_server YAML file), decoded
    once by the loader: the scene, the truth and the list of a simulation's inputs take ``plan``."""

    map: str  # absolute path of the map_server YAML
    surface: str
    plan: RosMap = field(compare=False, repr=False)  # the map and its image as map_server reads them


@dataclass(frozen=True)
class Robot:
    radius: float = 0.25


@dataclass(frozen=True)
class Trajectory:
    """Either waypoints driven at ``speed`` with a scan every ``scan_period`` s, or explicit poses.

    ``poses`` holds (x, y, yaw) with yaw in radians; when it is non-empty, waypoints are empty
    and scans are ``scan_period`` seconds apart. ``turn_rate`` (rad/s) > 0 turns the robot in
    place at each waypoint at that rate; 0 (the default) turns it at once.
    """

    waypoints: tuple[Point, ...] = ()
    speed: float = 0.3
    scan_period: float = 0.5
    poses: tuple[tuple[float, float, float], ...] = ()
    turn_rate: float = 0.0


@dataclass(frozen=True)
class Sonar:
    """The sonar ring: mounts (x, y, yaw) in the robot frame and the beam's properties.

    The beam's defaults are ``SensorSpec``'s, the sonar defaults of every log.
    """

    mounts: tuple[tuple[float, float, float], ...]
    beam_width: float = SensorSpec.beam_width
    min_range: float = SensorSpec.min_range
    max_range: float = SensorSpec.max_range
    noise_sigma: float = SensorSpec.noise_sigma
    random_rate: float = 0.02
    sub_rays: int = 11
    max_bounces: int = 2
    cause_tolerance: float = 0.1


@dataclass(frozen=True)
class Odometry:
    """Dead-reckoning drift of the logged poses: the odometry motion model of Probabilistic
    Robotics (table 5.6) between consecutive scans, each step's relative motion (rot1, trans,
    rot2) drawn with Gaussian errors of std ``translation * |trans|`` for trans and
    ``sqrt((rotation * rot)^2 + rotation_per_metre^2 * trans^2 / 2)`` for rot1 and rot2.

    ``translation`` m/m, ``rotation`` rad/rad, ``rotation_per_metre`` rad/m; all zero (the
    default) logs the true poses.

    The systematic errors of UMBmark (Borenstein & Feng 1996) add the same bias to every step:
    ``heading_bias_per_metre`` (rad/m, signed; unequal wheel diameters, E_d) turns the logged
    heading by that much per metre driven, half before and half after the step, and
    ``turn_bias`` (rad/rad, signed; a wrong wheelbase, E_b) scales every logged turn by
    ``1 + turn_bias``.
    """

    translation: float = 0.0
    rotation: float = 0.0
    rotation_per_metre: float = 0.0
    heading_bias_per_metre: float = 0.0
    turn_bias: float = 0.0

    @property
    def random_off(self) -> bool:
        return self.translation == 0.0 and self.rotation == 0.0 and self.rotation_per_metre == 0.0

    @property
    def off(self) -> bool:
        return self.random_off and self.heading_bias_per_metre == 0.0 and self.turn_bias == 0.0


@dataclass(frozen=True)
class EchoStrength:
    """The weakest echo a sonar detects. A sub-ray's echo has the strength
    ``exp(-2 theta^2 / beam^2) * cos(incidence)^incidence_exponent / path^2`` (theta the sub-ray's
    angle off the sensor axis, path in metres) and is not detected below ``min_strength``
    (1/m^2; 0, the default, detects every echo). ``beam`` is theta0 of the Kuc & Siegel beam
    pattern, in radians.
    """

    min_strength: float = 0.0
    beam: float = math.radians(15.0)
    incidence_exponent: float = 2.0


@dataclass(frozen=True)
class Firing:
    """The ring fires in a fixed cycle, one slot after another ``interval`` seconds apart, and
    each scan holds every sonar's latest reading: cast from the true pose when that sonar last
    fired, repeated unchanged by the scans until it fires again, logged with the scan's pose.
    ``slots`` holds each sonar's slot in the order of the mounts (sonars sharing a slot fire
    together); empty means 0, 1, ..., one sonar after another. ``interval`` 0 (the default) fires
    the whole ring at each scan's pose.
    """

    interval: float = 0.0
    slots: tuple[int, ...] = ()

    @property
    def on(self) -> bool:
        return self.interval > 0.0


@dataclass(frozen=True)
class SideLobes:
    """A weak side lobe on either side of the beam, ``angle`` (rad) off the axis and ``width``
    (rad) wide, cast with ``sub_rays`` sub-rays each side: its echo is detected when
    ``cos(incidence)^n / path^2 >= 1 / range^2`` (n the echo strength's incidence exponent), so
    only near surfaces are heard through it. ``range`` 0 (the default) has no side lobes. The
    default angle and width are the first side lobe of a circular piston of radius 19.2 mm at
    49.4 kHz (a Polaroid transducer) where its two-way strength is within half of its peak.
    """

    range: float = 0.0
    angle: float = math.radians(17.5)
    width: float = math.radians(5.5)
    sub_rays: int = 3


@dataclass(frozen=True)
class SimulationErrors:
    """The errors of a real robot that the simulator adds; the defaults are all off.

    ``noise_per_metre`` (m/m) makes the range noise's std ``noise_sigma + noise_per_metre * z``;
    ``crosstalk_rate`` is the probability that a reading takes a neighbouring sonar's echo when
    that one is nearer (logged as cause 3, specular or multipath); ``firing`` spreads the ring's
    readings over time while the robot moves; ``side_lobes`` hear near surfaces off the cone.
    """

    odometry: Odometry = field(default_factory=Odometry)
    noise_per_metre: float = 0.0
    crosstalk_rate: float = 0.0
    echo_strength: EchoStrength = field(default_factory=EchoStrength)
    firing: Firing = field(default_factory=Firing)
    side_lobes: SideLobes = field(default_factory=SideLobes)


@dataclass(frozen=True)
class PassableCheck:
    """A robot of ``robot_radius`` can go from ``start`` to ``goal`` through believed-free cells."""

    name: str
    start: Point
    goal: Point
    robot_radius: float

    kind = "passable"  # the check's key in the world file and in a log's /truth checks

    def as_json(self) -> dict:
        return {
            "name": self.name,
            self.kind: {"from": list(self.start), "to": list(self.goal), "robot_radius": self.robot_radius},
        }


@dataclass(frozen=True)
class BlockedCheck(PassableCheck):
    """No robot of ``robot_radius`` can go from ``start`` to ``goal``: the map holds the wall
    between them (the path ``PassableCheck`` looks for does not exist)."""

    kind = "blocked"


@dataclass(frozen=True)
class World:
    """Everything ``aogm simulate`` needs: geometry, surfaces, robot, trajectory, sonar, errors and checks."""

    name: str
    source: str  # path of the YAML file
    text: str  # the YAML text, written into every log
    bounds: tuple[float, float, float, float]  # x_min, y_min, x_max, y_max
    truth_resolution: float
    surfaces: dict[str, Surface]
    walls: tuple[Wall, ...] = ()
    boxes: tuple[Box, ...] = ()
    polygons: tuple[Polygon, ...] = ()
    circles: tuple[Circle, ...] = ()
    floorplan: Floorplan | None = None
    robot: Robot = field(default_factory=Robot)
    trajectory: Trajectory = field(default_factory=Trajectory)
    sonar: Sonar | None = None
    errors: SimulationErrors = field(default_factory=SimulationErrors)
    checks: tuple[PassableCheck | BlockedCheck, ...] = ()
    description: str = ""
