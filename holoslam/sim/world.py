"""The reference household of seed 002: floor plan, furniture and 35 QR-labelled objects.

A home of 9.5 m x 10.5 m (x east, y north, origin at the south-west outer corner, frame ``map``):

- balcony      x 0.0-5.5, y 0.0-1.5      (sliding door to the living room)
- living room  x 0.0-5.5, y 1.5-7.0
- kitchen      x 5.5-9.5, y 0.0-3.0
- dining room  x 5.5-9.5, y 3.0-7.0
- bedroom 1    x 0.0-3.5, y 7.0-10.5
- bedroom 2    x 3.5-6.3, y 7.0-10.5
- study        x 6.3-9.5, y 7.0-10.5

Walls are zero-thickness line segments with doorway gaps of 0.9-1.2 m; furniture is a set of convex
polygons with a height (solid from the floor up, so the laser at 0.3 m sees them and a camera ray at a
label's height is blocked by furniture at least that tall). Each object carries a QR label: its payload
(``holoslam.vision.label`` format, with the printed side ``s`` in mm), the label centre (x, y, z) in ``map``,
the yaw of the label normal (the direction the printed face looks at) and the printed side in metres.

Optional extras, for testing what holoslam makes of them (``reference_household(wall_codes=, sizeless_labels=)``,
both 0 in the reference household): ``wall_codes`` foreign QR codes fixed to walls (a Wi-Fi sticker, a poster,
a manual link, a product code...: ``World.codes``, ids ``holoslam.vision.label.foreign_code_id(payload)``),
and ``sizeless_labels`` objects whose label carries no printed size (``s`` left out of the payload: they can
only be located by triangulation).

``reachable`` is computed, not declared: an object is reachable when some point of the free space a
``ROBOT_RADIUS`` robot can stand in (connected to the start) lies within ``ARM_REACH`` of the label centre
(horizontal distance). The dining chair stored in the north-east corner behind the dining table is the one
object out of reach.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from holoslam.maps.grid import cells_to_world, world_to_cells
from holoslam.vision.label import ObjectLabel, encode_label

__all__ = [
    "Room",
    "Doorway",
    "Furniture",
    "WorldObject",
    "World",
    "reference_household",
    "world_to_json",
    "world_from_json",
    "raycast",
    "free_space",
    "FreeSpace",
    "ROBOT_RADIUS",
    "ARM_REACH",
    "WALL_CODES",
    "SIZELESS_ORDER",
]

ROBOT_RADIUS = 0.25  # m, a Pioneer III-sized base (about 0.5 m across)
ARM_REACH = 0.9  # m, horizontal reach of the manipulator from the base centre


@dataclass(frozen=True, slots=True)
class Room:
    name: str
    xmin: float
    ymin: float
    xmax: float
    ymax: float

    def contains(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return (
            (xy[:, 0] >= self.xmin)
            & (xy[:, 0] < self.xmax)
            & (xy[:, 1] >= self.ymin)
            & (xy[:, 1] < self.ymax)
        )


@dataclass(frozen=True, slots=True)
class Doorway:
    """A gap in a wall between two rooms: the gap's end points p0, p1 (on the wall line)."""

    name: str
    rooms: tuple[str, str]
    p0: tuple[float, float]
    p1: tuple[float, float]

    @property
    def width(self) -> float:
        return math.dist(self.p0, self.p1)

    @property
    def centre(self) -> tuple[float, float]:
        return ((self.p0[0] + self.p1[0]) / 2, (self.p0[1] + self.p1[1]) / 2)


@dataclass(frozen=True, slots=True)
class Furniture:
    name: str
    room: str
    polygon: tuple[tuple[float, float], ...]  # convex, counter-clockwise
    height: float


@dataclass(frozen=True, slots=True)
class WorldObject:
    object_id: str
    kind: str
    room: str
    payload: str
    position: tuple[float, float, float]  # label centre in map
    label_yaw: float  # yaw of the label's outward normal in map
    label_size: float  # printed side of the code in metres (quiet zone excluded)
    furniture: str | None = None  # the furniture the label is fixed on
    reachable: bool = True


@dataclass(frozen=True, slots=True)
class World:
    width: float
    height: float
    rooms: tuple[Room, ...]
    walls: tuple[tuple[float, float, float, float], ...]  # (x0, y0, x1, y1)
    doorways: tuple[Doorway, ...]
    furniture: tuple[Furniture, ...]
    objects: tuple[WorldObject, ...]
    magnetic_sources: tuple[tuple[str, float, float, float], ...] = ()  # (name, x, y, amplitude_deg)
    codes: tuple[WorldObject, ...] = ()  # foreign QR codes on walls (not objects; kind "wall_code")

    @property
    def all_codes(self) -> tuple[WorldObject, ...]:
        """Every printed code the camera can see: the objects' labels, then the wall codes."""
        return self.objects + self.codes

    def wall_segments(self) -> np.ndarray:
        """Walls as an (M, 4) float64 array of (x0, y0, x1, y1)."""
        return np.asarray(self.walls, dtype=np.float64).reshape(-1, 4)

    def furniture_segments(self, min_height: float = 0.0, exclude: str | None = None) -> np.ndarray:
        """Edges of the furniture at least ``min_height`` tall, (K, 4)."""
        segs = []
        for f in self.furniture:
            if f.height < min_height or f.name == exclude:
                continue
            p = np.asarray(f.polygon, dtype=np.float64)
            q = np.roll(p, -1, axis=0)
            segs.append(np.hstack([p, q]))
        return np.vstack(segs) if segs else np.zeros((0, 4))

    def obstacle_segments(self) -> np.ndarray:
        """Everything a planar laser at 0.3 m sees: walls and furniture edges, (M, 4)."""
        return np.vstack([self.wall_segments(), self.furniture_segments()])

    def room_of(self, xy: np.ndarray) -> list[str | None]:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out: list[str | None] = [None] * len(xy)
        for r in self.rooms:
            for i in np.flatnonzero(r.contains(xy)):
                out[i] = r.name
        return out

    def object(self, object_id: str) -> WorldObject:
        """The object, or wall code, with this id."""
        for o in self.all_codes:
            if o.object_id == object_id:
                return o
        raise KeyError(object_id)


def _rect(x0: float, y0: float, x1: float, y1: float) -> tuple[tuple[float, float], ...]:
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


def _wall_with_gaps(p: tuple[float, float], q: tuple[float, float], gaps: list[tuple[float, float]]):
    """Split the axis-aligned wall p-q into segments around the gaps (given as intervals along the wall)."""
    horizontal = p[1] == q[1]
    a, b = (p[0], q[0]) if horizontal else (p[1], q[1])
    cuts = [a]
    for g0, g1 in sorted(gaps):
        cuts += [g0, g1]
    cuts.append(b)
    out = []
    for s, e in zip(cuts[0::2], cuts[1::2], strict=True):
        if e - s > 1e-9:
            out.append((s, p[1], e, p[1]) if horizontal else (p[0], s, p[0], e))
    return out


# (id, type, room, furniture, (x, y, z), label yaw [deg], side [mm], attributes)
_OBJECTS: list[tuple] = [
    ("O01", "sofa", "living_room", "sofa", (0.96, 4.10, 0.45), 0, 120, "g=none,m=45"),
    ("O02", "air_conditioner", "living_room", None, (0.20, 2.30, 2.00), 0, 150, "g=none,m=12"),
    ("O03", "tv", "living_room", "tv_stand", (4.99, 3.20, 0.95), 180, 120, "g=none,m=9,f=1"),
    ("O04", "coffee_table", "living_room", "coffee_table", (2.10, 3.49, 0.38), -90, 100, "g=none,m=15"),
    ("O05", "cup", "living_room", "coffee_table", (1.80, 3.56, 0.50), -90, 60, "g=handle,m=0.3,f=1"),
    ("O06", "remote", "living_room", "coffee_table", (2.51, 4.40, 0.47), 0, 50, "g=top,m=0.2"),
    ("O07", "armchair", "living_room", "armchair", (0.91, 6.15, 0.45), 0, 120, "g=none,m=20"),
    ("O08", "lamp", "living_room", "lamp", (0.61, 6.75, 1.20), 0, 80, "g=side,m=3,f=1"),
    ("O09", "plant", "balcony", "plant_pot", (0.71, 0.52, 0.50), 0, 80, "g=side,m=6"),
    ("O10", "washing_machine", "balcony", "washing_machine", (4.69, 0.45, 0.70), 180, 120, "g=none,m=60"),
    ("O11", "watering_can", "balcony", "plant_pot", (0.71, 0.22, 0.62), 0, 50, "g=handle,m=1"),
    ("O12", "cup", "balcony", "balcony_table", (2.60, 0.56, 0.75), 90, 60, "g=handle,m=0.3,f=1"),
    ("O13", "fridge", "kitchen", "fridge", (8.79, 1.55, 1.30), 180, 150, "g=none,m=70"),
    ("O14", "microwave", "kitchen", "counter", (6.20, 0.66, 1.05), 90, 100, "g=none,m=12,f=1"),
    ("O15", "kettle", "kitchen", "counter", (7.10, 0.66, 1.00), 90, 60, "g=handle,m=1.2"),
    ("O16", "cup", "kitchen", "counter", (7.80, 0.66, 0.97), 90, 60, "g=handle,m=0.3,f=1"),
    ("O17", "bowl", "kitchen", "counter", (8.40, 0.66, 0.95), 90, 50, "g=top,m=0.4,f=1"),
    ("O18", "dining_table", "dining_room", "dining_table", (7.59, 5.80, 0.65), 180, 100, "g=none,m=30"),
    ("O19", "chair", "dining_room", "chair_w", (7.09, 5.50, 0.80), 180, 100, "g=side,m=5"),
    ("O20", "chair", "dining_room", "chair_s1", (8.10, 4.49, 0.80), -90, 100, "g=side,m=5"),
    ("O21", "chair", "dining_room", "chair_s2", (8.70, 4.49, 0.80), -90, 100, "g=side,m=5"),
    ("O22", "chair", "dining_room", "chair_corner", (9.30, 6.61, 0.80), -90, 100, "g=side,m=5"),
    ("O23", "cabinet", "dining_room", "cabinet", (6.20, 3.51, 0.70), 90, 120, "g=none,m=40"),
    ("O24", "plate", "dining_room", "cabinet", (6.60, 3.51, 0.95), 90, 60, "g=side,m=0.5,f=1"),
    ("O25", "bed", "bedroom_1", "bed_1", (1.10, 8.59, 0.45), -90, 120, "g=none,m=50"),
    ("O26", "wardrobe", "bedroom_1", "wardrobe_1", (2.79, 9.70, 1.10), 180, 120, "g=none,m=80"),
    ("O27", "alarm_clock", "bedroom_1", "nightstand_1", (0.56, 8.33, 0.60), 0, 50, "g=top,m=0.3"),
    ("O28", "bed", "bedroom_2", "bed_2", (5.20, 8.79, 0.45), -90, 120, "g=none,m=50"),
    ("O29", "wardrobe", "bedroom_2", "wardrobe_2", (4.11, 8.10, 1.10), 0, 120, "g=none,m=80"),
    ("O30", "book", "bedroom_2", "nightstand_2", (6.09, 8.30, 0.60), 180, 50, "g=side,m=0.6"),
    ("O31", "desk", "study", "desk", (8.80, 9.59, 0.60), -90, 100, "g=none,m=25"),
    ("O32", "bookshelf", "study", "bookshelf", (9.09, 8.40, 1.20), 180, 120, "g=none,m=40"),
    ("O33", "laptop", "study", "desk", (8.40, 9.61, 0.80), -90, 60, "g=side,m=1.8,f=1"),
    ("O34", "cup", "study", "desk", (9.05, 9.61, 0.80), -90, 60, "g=handle,m=0.3,f=1"),
    ("O35", "office_chair", "study", "office_chair", (7.71, 8.90, 0.70), 180, 100, "g=side,m=8"),
]


# Foreign codes on walls: (payload, room, (x, y, z) of the code centre, yaw of its normal [deg], side [mm]); each a
# centimetre off its wall, above the furniture, where the tour passes within the camera's range.
WALL_CODES: list[tuple[str, str, tuple[float, float, float], float, int]] = [
    ("WIFI:S:home-5G;T:WPA;P:correct horse battery;;", "living_room", (3.4, 6.99, 1.45), -90, 120),
    ("https://example.com/manual/washer-WM1200", "balcony", (3.8, 0.01, 1.25), 90, 120),
    ("https://example.com/fridge/FR-450?lang=en", "kitchen", (9.49, 2.6, 1.40), 180, 120),
    ("4006381333931", "kitchen", (8.6, 2.99, 1.50), -90, 100),
    ("BEGIN:VCARD\nN:Plumber;Joe\nTEL:+441234567890\nEND:VCARD", "dining_room", (9.49, 3.9, 1.45), 180, 140),
    ("https://example.com/menu", "dining_room", (8.6, 6.99, 1.50), -90, 110),
    ("tel:+441234567890", "study", (6.31, 9.6, 1.45), 0, 100),
    ("https://example.com/poster/2026", "bedroom_1", (3.49, 8.0, 1.50), 180, 150),
    ("geo:51.5007,-0.1246", "bedroom_2", (6.29, 7.6, 1.45), 180, 110),
    ("https://example.com/thermostat/T-22", "living_room", (5.49, 2.0, 1.40), 180, 110),
    ("SMSTO:+441234567890:hello", "living_room", (1.0, 1.51, 1.40), 90, 100),
    ("https://example.com/lamp", "bedroom_1", (0.01, 7.6, 1.50), 0, 110),
]
# The objects whose labels lose their printed size, in this order (``sizeless_labels`` takes the first k).
SIZELESS_ORDER = ("O13", "O03", "O10", "O32", "O18", "O29", "O07", "O26")


def reference_household(wall_codes: int = 0, sizeless_labels: int = 0) -> World:
    """The reference household (deterministic; no randomness in the world itself). ``wall_codes`` (0 to
    ``len(WALL_CODES)``) foreign codes on walls and ``sizeless_labels`` (0 to ``len(SIZELESS_ORDER)``) labels
    without a printed size can be added for tests; the reference household has neither."""
    if not (0 <= wall_codes <= len(WALL_CODES)) or not (0 <= sizeless_labels <= len(SIZELESS_ORDER)):
        raise ValueError(
            f"wall_codes must be 0..{len(WALL_CODES)} and sizeless_labels 0..{len(SIZELESS_ORDER)}, got "
            f"{wall_codes} and {sizeless_labels}"
        )
    sizeless = set(SIZELESS_ORDER[:sizeless_labels])
    W, H = 9.5, 10.5
    rooms = (
        Room("balcony", 0.0, 0.0, 5.5, 1.5),
        Room("living_room", 0.0, 1.5, 5.5, 7.0),
        Room("kitchen", 5.5, 0.0, 9.5, 3.0),
        Room("dining_room", 5.5, 3.0, 9.5, 7.0),
        Room("bedroom_1", 0.0, 7.0, 3.5, 10.5),
        Room("bedroom_2", 3.5, 7.0, 6.3, 10.5),
        Room("study", 6.3, 7.0, 9.5, 10.5),
    )
    doorways = (
        Doorway("balcony_door", ("living_room", "balcony"), (2.0, 1.5), (3.1, 1.5)),
        Doorway("bedroom_1_door", ("living_room", "bedroom_1"), (1.5, 7.0), (2.45, 7.0)),
        Doorway("bedroom_2_door", ("living_room", "bedroom_2"), (4.3, 7.0), (5.25, 7.0)),
        Doorway("dining_door", ("living_room", "dining_room"), (5.5, 4.5), (5.5, 5.7)),
        Doorway("kitchen_door", ("dining_room", "kitchen"), (6.9, 3.0), (7.9, 3.0)),
        Doorway("study_door", ("dining_room", "study"), (6.45, 7.0), (7.4, 7.0)),
    )
    walls: list[tuple[float, float, float, float]] = [
        (0.0, 0.0, W, 0.0),
        (W, 0.0, W, H),
        (W, H, 0.0, H),
        (0.0, H, 0.0, 0.0),
    ]
    walls += _wall_with_gaps((0.0, 1.5), (5.5, 1.5), [(2.0, 3.1)])
    walls += _wall_with_gaps((0.0, 7.0), (9.5, 7.0), [(1.5, 2.45), (4.3, 5.25), (6.45, 7.4)])
    walls += _wall_with_gaps((5.5, 0.0), (5.5, 7.0), [(4.5, 5.7)])
    walls += _wall_with_gaps((5.5, 3.0), (9.5, 3.0), [(6.9, 7.9)])
    walls += _wall_with_gaps((3.5, 7.0), (3.5, 10.5), [])
    walls += _wall_with_gaps((6.3, 7.0), (6.3, 10.5), [])

    F = Furniture
    furniture = (
        F("sofa", "living_room", _rect(0.05, 3.0, 0.95, 5.2), 0.85),
        F("coffee_table", "living_room", _rect(1.7, 3.5, 2.5, 4.7), 0.45),
        F("tv_stand", "living_room", _rect(5.0, 2.5, 5.45, 3.9), 0.55),
        F("armchair", "living_room", _rect(0.1, 5.8, 0.9, 6.5), 0.8),
        F("lamp", "living_room", _rect(0.1, 6.55, 0.6, 6.95), 1.5),
        F("plant_pot", "balcony", _rect(0.05, 0.05, 0.7, 0.7), 0.6),
        F("washing_machine", "balcony", _rect(4.7, 0.05, 5.45, 0.8), 0.85),
        F("balcony_table", "balcony", _rect(2.2, 0.05, 3.0, 0.55), 0.7),
        F("counter", "kitchen", _rect(5.55, 0.05, 9.45, 0.65), 0.9),
        F("fridge", "kitchen", _rect(8.8, 1.2, 9.45, 1.9), 1.8),
        F("cabinet", "dining_room", _rect(5.55, 3.05, 6.8, 3.5), 0.9),
        F("dining_table", "dining_room", _rect(7.6, 5.0, 9.1, 6.6), 0.75),
        F("chair_w", "dining_room", _rect(7.1, 5.3, 7.55, 5.75), 0.9),
        F("chair_s1", "dining_room", _rect(7.9, 4.5, 8.3, 4.95), 0.9),
        F("chair_s2", "dining_room", _rect(8.5, 4.5, 8.9, 4.95), 0.9),
        F("chair_corner", "dining_room", _rect(9.12, 6.62, 9.48, 6.98), 0.9),
        F("bed_1", "bedroom_1", _rect(0.05, 8.6, 2.1, 10.45), 0.55),
        F("wardrobe_1", "bedroom_1", _rect(2.8, 9.0, 3.45, 10.45), 2.0),
        F("nightstand_1", "bedroom_1", _rect(0.05, 8.05, 0.55, 8.55), 0.55),
        F("bed_2", "bedroom_2", _rect(4.2, 8.8, 6.25, 10.45), 0.55),
        F("wardrobe_2", "bedroom_2", _rect(3.55, 7.6, 4.1, 8.8), 2.0),
        F("nightstand_2", "bedroom_2", _rect(6.1, 8.05, 6.25, 8.55), 0.55),
        F("desk", "study", _rect(8.0, 9.6, 9.45, 10.45), 0.75),
        F("bookshelf", "study", _rect(9.1, 7.5, 9.45, 9.3), 1.9),
        F("office_chair", "study", _rect(7.2, 8.7, 7.7, 9.1), 0.7),
    )
    magnetic_sources = (
        ("fridge", 9.1, 1.55, 6.0),
        ("tv", 5.2, 3.2, 4.0),
        ("air_conditioner", 0.3, 2.3, 3.0),
        ("washing_machine", 5.05, 0.45, 5.0),
        ("microwave", 6.2, 0.35, 4.0),
    )
    objects = []
    for oid, kind, room, furn, pos, yaw_deg, side_mm, attrs in _OBJECTS:
        pairs = tuple(tuple(kv.split("=", 1)) for kv in attrs.split(","))
        if oid not in sizeless:
            pairs += (("s", str(side_mm)),)
        payload = encode_label(ObjectLabel(oid, kind, pairs))
        objects.append(
            WorldObject(
                oid,
                kind,
                room,
                payload,
                (float(pos[0]), float(pos[1]), float(pos[2])),
                math.radians(yaw_deg),
                side_mm / 1000.0,
                furn,
            )
        )
    world = World(W, H, rooms, tuple(walls), doorways, furniture, tuple(objects), magnetic_sources)
    fs = free_space(world)
    reach = fs.reachable_within(np.array([o.position[:2] for o in objects]), ARM_REACH, world.wall_segments())
    objects = [
        WorldObject(
            o.object_id,
            o.kind,
            o.room,
            o.payload,
            o.position,
            o.label_yaw,
            o.label_size,
            o.furniture,
            bool(r),
        )
        for o, r in zip(objects, reach, strict=True)
    ]
    from holoslam.vision.label import foreign_code_id

    codes = tuple(
        WorldObject(foreign_code_id(text), "wall_code", room, text, pos, math.radians(yaw), mm / 1000.0, None,
                    False)
        for text, room, pos, yaw, mm in WALL_CODES[:wall_codes]
    )
    return World(W, H, rooms, tuple(walls), doorways, furniture, tuple(objects), magnetic_sources, codes)


# ---------------------------------------------------------------------------------------------- free space


@dataclass(frozen=True)
class FreeSpace:
    """A raster of the home: ``clearance`` (metres from the cell centre to the nearest wall or furniture, 0
    inside furniture or outside the home), ``standable`` (cells where a ``robot_radius`` base fits and that
    connect to ``seed_xy``). Row 0 is the lowest y."""

    resolution: float
    origin: tuple[float, float]
    clearance: np.ndarray
    standable: np.ndarray
    robot_radius: float

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, c = world_to_cells(xy, self.origin[0], self.origin[1], self.resolution).T
        return np.clip(r, 0, self.clearance.shape[0] - 1), np.clip(c, 0, self.clearance.shape[1] - 1)

    def xy_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        rc = np.column_stack([np.ravel(rows), np.ravel(cols)])
        return cells_to_world(rc, self.origin[0], self.origin[1], self.resolution)

    def clearance_at(self, xy: np.ndarray) -> np.ndarray:
        r, c = self.cell_of(xy)
        return self.clearance[r, c]

    def reachable_within(self, xy: np.ndarray, reach: float, walls: np.ndarray | None = None) -> np.ndarray:
        """For each point, whether a standable cell centre lies within ``reach`` (horizontal distance) with
        no wall of ``walls`` (M, 4) in between (an arm does not reach through a wall)."""
        rr, cc = np.nonzero(self.standable)
        pts = self.xy_of(rr, cc)
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(xy), dtype=bool)
        for i, p in enumerate(xy):
            near = pts[((pts - p) ** 2).sum(-1) <= reach * reach]
            if len(near) and walls is not None:
                near = near[~segments_block(walls, near, np.broadcast_to(p, near.shape))]
            out[i] = len(near) > 0
        return out


def free_space(
    world: World,
    resolution: float = 0.02,
    robot_radius: float = ROBOT_RADIUS,
    seed_xy: tuple[float, float] = (3.0, 4.0),
) -> FreeSpace:
    """Rasterise walls and furniture and compute clearance with a distance transform (vectorised)."""
    import cv2

    nx = int(round(world.width / resolution))
    ny = int(round(world.height / resolution))
    occ = np.zeros((ny, nx), dtype=np.uint8)

    def to_px(p):
        return (int(round(p[0] / resolution * 16)), int(round(p[1] / resolution * 16)))

    for x0, y0, x1, y1 in world.walls:
        cv2.line(occ, to_px((x0, y0)), to_px((x1, y1)), 1, 1, cv2.LINE_8, 4)
    for f in world.furniture:
        poly = np.array([to_px(p) for p in f.polygon], dtype=np.int32)
        cv2.fillPoly(occ, [poly], 1, cv2.LINE_8, 4)
    occ[0, :] = occ[-1, :] = 1
    occ[:, 0] = occ[:, -1] = 1
    dist = cv2.distanceTransform((occ == 0).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    clearance = dist.astype(np.float64) * resolution
    fits = (clearance >= robot_radius).astype(np.uint8)
    _, labels = cv2.connectedComponents(fits, connectivity=8)
    sr = int((seed_xy[1]) / resolution)
    sc = int((seed_xy[0]) / resolution)
    standable = (labels == labels[sr, sc]) & (fits > 0)
    return FreeSpace(resolution, (0.0, 0.0), clearance, standable, robot_radius)


# ---------------------------------------------------------------------------------------------- ray casting


def raycast(segments: np.ndarray, origins: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
    """Ranges from ``origins`` (N, 2) along ``angles`` (N, B) to the nearest of ``segments`` (M, 4);
    ``inf`` where nothing lies within ``max_range``. Vectorised over N x B x M."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 2)
    ang = np.asarray(angles, dtype=np.float64).reshape(o.shape[0], -1)
    dx, dy = np.cos(ang)[..., None], np.sin(ang)[..., None]  # (N, B, 1)
    px, py = seg[:, 0], seg[:, 1]
    ex, ey = seg[:, 2] - px, seg[:, 3] - py  # (M,)
    wx = px[None, None, :] - o[:, 0, None, None]
    wy = py[None, None, :] - o[:, 1, None, None]
    den = dx * ey - dy * ex  # cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / den
        u = (wx * dy - wy * dx) / den
    ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0.0) & (u <= 1.0)
    t = np.where(ok, t, np.inf)
    r = t.min(axis=-1)
    r[r > max_range] = np.inf
    return r


def segments_block(segments: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether the open segments a[i]-b[i] (N, 2) cross any of ``segments`` (M, 4), (N,) bool."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    if len(seg) == 0:
        return np.zeros(len(a), dtype=bool)
    d = b - a
    dx, dy = d[:, 0, None], d[:, 1, None]
    ex, ey = seg[None, :, 2] - seg[None, :, 0], seg[None, :, 3] - seg[None, :, 1]
    wx, wy = seg[None, :, 0] - a[:, 0, None], seg[None, :, 1] - a[:, 1, None]
    den = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / den
        u = (wx * dy - wy * dx) / den
    hit = (np.abs(den) > 1e-12) & (t > 1e-6) & (t < 1 - 1e-6) & (u >= 0) & (u <= 1)
    return np.asarray(hit.any(axis=1))


# ---------------------------------------------------------------------------------------------- JSON


def world_to_json(world: World) -> str:
    """The world as the JSON text carried on ``/ground_truth/world`` (compact, stable key order)."""
    d = {
        "format": "holoslam-world-1",
        "frame_id": "map",
        "width": world.width,
        "height": world.height,
        "rooms": [
            {"name": r.name, "xmin": r.xmin, "ymin": r.ymin, "xmax": r.xmax, "ymax": r.ymax}
            for r in world.rooms
        ],
        "walls": [list(w) for w in world.walls],
        "doorways": [
            {
                "name": d.name,
                "rooms": list(d.rooms),
                "p0": list(d.p0),
                "p1": list(d.p1),
                "width": round(d.width, 6),
            }
            for d in world.doorways
        ],
        "furniture": [
            {"name": f.name, "room": f.room, "polygon": [list(p) for p in f.polygon], "height": f.height}
            for f in world.furniture
        ],
        "objects": [
            {
                "id": o.object_id,
                "type": o.kind,
                "room": o.room,
                "payload": o.payload,
                "position": list(o.position),
                "label_yaw": o.label_yaw,
                "label_size": o.label_size,
                "furniture": o.furniture,
                "reachable": o.reachable,
            }
            for o in world.objects
        ],
        "magnetic_sources": [
            {"name": n, "x": x, "y": y, "amplitude_deg": a} for n, x, y, a in world.magnetic_sources
        ],
    }
    if world.codes:  # only when there are any: the reference household's JSON stays as it was
        d["codes"] = [
            {
                "id": c.object_id,
                "type": c.kind,
                "room": c.room,
                "payload": c.payload,
                "position": list(c.position),
                "label_yaw": c.label_yaw,
                "label_size": c.label_size,
            }
            for c in world.codes
        ]
    return json.dumps(d, separators=(",", ":"))


def world_from_json(text: str) -> World:
    """Inverse of ``world_to_json``."""
    d = json.loads(text)
    return World(
        width=float(d["width"]),
        height=float(d["height"]),
        rooms=tuple(Room(r["name"], r["xmin"], r["ymin"], r["xmax"], r["ymax"]) for r in d["rooms"]),
        walls=tuple((float(w[0]), float(w[1]), float(w[2]), float(w[3])) for w in d["walls"]),
        doorways=tuple(
            Doorway(x["name"], tuple(x["rooms"]), tuple(x["p0"]), tuple(x["p1"])) for x in d["doorways"]
        ),
        furniture=tuple(
            Furniture(f["name"], f["room"], tuple(tuple(p) for p in f["polygon"]), f["height"])
            for f in d["furniture"]
        ),
        objects=tuple(
            WorldObject(
                o["id"],
                o["type"],
                o["room"],
                o["payload"],
                tuple(o["position"]),
                o["label_yaw"],
                o["label_size"],
                o["furniture"],
                o["reachable"],
            )
            for o in d["objects"]
        ),
        magnetic_sources=tuple(
            (m["name"], m["x"], m["y"], m["amplitude_deg"]) for m in d.get("magnetic_sources", [])
        ),
        codes=tuple(
            WorldObject(c["id"], c["type"], c["room"], c["payload"], tuple(c["position"]), c["label_yaw"],
                        c["label_size"], None, False)
            for c in d.get("codes", [])
        ),
    )
