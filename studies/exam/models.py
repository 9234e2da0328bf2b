"""The exam's two wrist models, from published parameters, built with OpenSim's API.

Neither is ikid's body model (``ikid.body_model()``; none of its numbers is used here). Both
are written as one description, :class:`WristModel` — a forearm body fixed in the lab and a
chain of single-axis rotations — from which ``build_osim`` makes the OpenSim model (the
simulator and the truth) and ``biomod.py`` the biorbd model of the very same body.

* ``rajagopal2016``: the right arm of Rajagopal et al. 2016 (opensim-models
  ``Models/Rajagopal/Rajagopal2016.osim``), whose forearm and wrist are Holzbaur et al.'s 2005
  MoBL-ARMS (its ``radioulnar_r`` pin about an oblique axis, then ``radius_hand_r``, a universal
  joint: flexion about the offset frame's x, then deviation about its y). Its segment masses,
  centres of mass and inertias, its joint centres, axes and ranges, its forearm markers.
* ``gonzalez1997``: the wrist of Gonzalez, Buchanan & Delp 1997 (opensim-models
  ``Models/WristModel/wrist.osim``): its pronation axis and centre, its wrist frame
  (``rotaxis``), its two carpal rows 20 mm apart with flexion about the rows' z and deviation
  about their x. The original splits each of flexion and deviation half and half between the
  two rows (coupled coordinates); here flexion turns the proximal row and deviation the distal
  row, each in full — non-intersecting axes biorbd can represent exactly (it has no coupled
  coordinates). The original has no masses (a muscle-path model): the hand and radius carry
  Winter's (2009, Table 4.1) segment parameters for a 75 kg subject.

What the exam assumes of both (as ikid's model and the thesis do): the forearm markers (and
the styloids) sit on the segment proximal to all three wrist rotations — the ulna, fixed in
the lab at the shoulder pose with the elbow extended — and pronation-supination turns the
radius and the hand with it. Each model's neutral posture is the middle of its
pronation-supination range with flexion and deviation at zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# Lab (OpenSim's and ikid's convention): X anterior, Y up, Z right. The forearm hangs from the
# shoulder, elbow extended, mid-prone; shoulder flexion turns it about lab Z.
GRAVITY = (0.0, -9.80665, 0.0)
# ISB forearm axes in the lab at zero shoulder flexion (x volar = lab -Z, y proximal = lab +Y,
# z radial = lab +X), the lab pose the exam's subject stands in.
FOREARM_IN_LAB = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
SHOULDER_IN_LAB = (0.0, 1.45, 0.17)  # the exam's lab, m (not ikid's)
# Tiny mass of the link between two rotations of one joint (a rigid-body model needs a mass).
LINK_MASS, LINK_INERTIA = 1e-6, 1e-9


def rot_xyz(angles: tuple[float, float, float]) -> np.ndarray:
    """OpenSim's body-fixed X-Y-Z orientation (``orientation`` of a frame) as a matrix."""
    a, b, c = angles
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return rx @ ry @ rz


def xyz_of(r: np.ndarray) -> tuple[float, float, float]:
    """Body-fixed X-Y-Z angles of a rotation matrix (inverse of :func:`rot_xyz`)."""
    b = math.asin(max(-1.0, min(1.0, r[0, 2])))
    a = math.atan2(-r[1, 2], r[2, 2])
    c = math.atan2(-r[0, 1], r[0, 0])
    return a, b, c


def axis_angle(axis: np.ndarray, q: float) -> np.ndarray:
    """Rotation by ``q`` about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(q) * k + (1 - math.cos(q)) * (k @ k)


@dataclass(frozen=True)
class Inertial:
    """Mass (kg), centre of mass (m) and inertia about it (kg·m², full 3x3), in the body's frame."""

    mass: float
    com: tuple[float, float, float]
    inertia: np.ndarray

    @staticmethod
    def principal(mass: float, com, moments, rotation: np.ndarray | None = None) -> Inertial:
        r = np.eye(3) if rotation is None else rotation
        return Inertial(mass, tuple(float(c) for c in com), r @ np.diag(moments) @ r.T)


LINK = Inertial.principal(LINK_MASS, (0.0, 0.0, 0.0), (LINK_INERTIA,) * 3)


@dataclass(frozen=True)
class Link:
    """One rotation of the chain: the body it moves, its parent, the model coordinate, the joint
    centre and unit axis in the parent's frame; the body's frame is the parent's, moved to the
    centre and turned by the coordinate (so at zero it has the parent's orientation)."""

    body: str
    parent: str
    coordinate: str
    centre: tuple[float, float, float]
    axis: tuple[float, float, float]
    range: tuple[float, float]
    inertial: Inertial


@dataclass(frozen=True)
class WristModel:
    """A forearm (``ulna``, fixed in the lab) and the wrist chain; points per body, m."""

    name: str
    source: str
    ulna: Inertial
    links: tuple[Link, ...]
    neutral: tuple[float, ...]
    #: Coordinate order for ikid's (s_p, e_f, ad_ab) meaning: the model's names.
    coordinates: tuple[str, ...]
    #: Anatomical points: name -> (body, point in the body's frame).
    points: dict[str, tuple[str, tuple[float, float, float]]] = field(default_factory=dict)
    #: Half-length of the upper arm + forearm, to place the wrist below the shoulder, m.
    arm_length: float = 0.55

    @property
    def hand(self) -> str:
        return self.links[-1].body

    def link_of(self, body: str) -> Link:
        return next(lk for lk in self.links if lk.body == body)

    def ranges(self) -> np.ndarray:
        return np.array([lk.range for lk in self.links])


# --- Rajagopal 2016 / MoBL-ARMS (Holzbaur 2005) --------------------------------------------------

# Rajagopal2016.osim, joint radioulnar_r: parent offset frame in ulna_r (translation, XYZ
# orientation); the pin turns about that frame's z.
_RAJ_PS_CENTRE = (-0.006727, -0.013007, 0.026083)
_RAJ_PS_FRAME = rot_xyz((-1.56884, 0.056428, 1.53614))
# Joint radius_hand_r (UniversalJoint): offset frame in radius_r; flexion about its x, then
# deviation about its y (carried by the flexion).
_RAJ_WR_CENTRE = (-0.008797, -0.235841, 0.01361)
_RAJ_WR_FRAME = rot_xyz((-1.5708, 0.0, -1.5708))
# Joint elbow_r: the ulna's origin in humerus_r at zero elbow flexion (both offset frames share
# one orientation, so at zero the ulna's frame is the humerus's moved there).
_RAJ_ELBOW = np.array((0.013144, -0.286273, -0.009595))


def _raj_in_ulna(p_radius: tuple[float, float, float], pro_sup: float) -> tuple[float, float, float]:
    """A point of the radius expressed in the ulna's frame at pronation ``pro_sup``."""
    r = axis_angle(_RAJ_PS_FRAME[:, 2], pro_sup)
    return tuple(float(v) for v in np.array(_RAJ_PS_CENTRE) + r @ np.array(p_radius))


def rajagopal2016() -> WristModel:
    neutral_ps = math.pi / 4  # middle of pro_sup_r's range 0..90°
    # Segment parameters: Rajagopal2016.osim bodies ulna_r, radius_r, hand_r (mass, mass_center,
    # inertia Ixx Iyy Izz; products zero).
    ulna = Inertial.principal(0.6075, (0.0, -0.120525, 0.0), (0.002962, 0.000618, 0.003213))
    radius = Inertial.principal(0.6075, (0.0, -0.120525, 0.0), (0.002962, 0.000618, 0.003213))
    hand = Inertial.principal(0.4575, (0.0, -0.068095, 0.0), (0.000892, 0.000547, 0.00134))
    links = (
        Link(
            "radius",
            "ulna",
            "pro_sup",
            _RAJ_PS_CENTRE,
            tuple(_RAJ_PS_FRAME[:, 2]),
            (0.0, math.pi / 2),  # pro_sup_r range
            radius,
        ),
        # The flexion link sits at the wrist centre; the hand's frame is the radius's at zero.
        Link(
            "wrist_flex_link",
            "radius",
            "wrist_flex",
            _RAJ_WR_CENTRE,
            tuple(_RAJ_WR_FRAME[:, 0]),
            (-1.22173048, 1.22173048),
            LINK,
        ),
        Link(
            "hand",
            "wrist_flex_link",
            "wrist_dev",
            (0.0, 0.0, 0.0),
            tuple(_RAJ_WR_FRAME[:, 1]),
            (-0.43633231, 0.61086524),
            hand,
        ),
    )
    # Epicondyles: markers RLEL, RMEL of humerus_r, moved into the ulna's frame. Forearm markers:
    # RFAsuperior (ulna_r) as the dorsal forearm point; RFAradius, RFAulna (radius_r, at the
    # wrist) as the radial and ulnar styloid points, carried onto the ulna at the neutral posture.
    lel = tuple(float(v) for v in np.array((0.015, -0.28, 0.04)) - _RAJ_ELBOW)
    mel = tuple(float(v) for v in np.array((0.00225, -0.286, -0.046)) - _RAJ_ELBOW)
    points = {
        "lateral_epicondyle": ("ulna", lel),
        "medial_epicondyle": ("ulna", mel),
        "radial_styloid": ("ulna", _raj_in_ulna((0.0005, -0.225, 0.05), neutral_ps)),
        "ulnar_styloid": ("ulna", _raj_in_ulna((-0.022, -0.225, -0.022), neutral_ps)),
        "forearm_dorsal": ("ulna", (0.0046045, -0.0800579, 0.0453196)),
        # The hand has no markers in the model: the metacarpal heads and 3rd base placed by us
        # on its dorsum (hand_r frame: x palmar, y proximal, z radial in the anatomical pose),
        # from its centre of mass 68 mm distal of the wrist (about 40 % of the hand's length).
        "mc2_head": ("hand", (-0.013, -0.090, 0.024)),
        "mc5_head": ("hand", (-0.011, -0.082, -0.029)),
        "mc3_base": ("hand", (-0.019, -0.032, 0.004)),
    }
    return WristModel(
        "rajagopal2016",
        "Rajagopal et al. 2016 (arm after Holzbaur et al. 2005, MoBL-ARMS)",
        ulna,
        links,
        (neutral_ps, 0.0, 0.0),
        ("pro_sup", "wrist_flex", "wrist_dev"),
        points,
        arm_length=0.286273 + 0.235841,  # humerus_r elbow offset + radius_r wrist offset
    )


# --- Gonzalez 1997 (OpenSim WristModel) ---------------------------------------------------------

# wrist.osim, joint radioulnar: pro_sup axis and centre in the ulna.
_GON_PS_CENTRE = (-0.0065, -0.008, 0.027)
_GON_PS_AXIS = (0.05639802, 0.98357739, -0.17144907)
# Weld rad-rotaxis: the wrist frame in the radius (translation, XYZ orientation).
_GON_ROTAXIS = np.array((-0.0085, -0.2313, 0.0561))
_GON_ROT = rot_xyz((-0.261799, 0.392699, 0.0))
# Joints rotaxis-auxprfem (proximal row centre in rotaxis) and auxprrud-auxdrfem (distal row
# 20 mm further, in the proximal row's frame).
_GON_PROX = _GON_ROTAXIS + _GON_ROT @ np.array((-0.001, 0.009, 0.0))
_GON_DIST = _GON_ROT @ np.array((0.001, -0.02, 0.0))


def gonzalez1997() -> WristModel:
    body_mass = 75.0
    # Winter 2009, Table 4.1 (Dempster): hand 0.006 M, centre of mass 0.506 of the wrist axis ->
    # 2nd knuckle of the middle finger (taken 0.10 m here), radius of gyration 0.297 of it about
    # the centre of mass; about the long axis half that inertia (Winter gives none: assumed).
    hl, hm = 0.10, 0.006 * body_mass
    it = hm * (0.297 * hl) ** 2
    hand = Inertial.principal(
        hm, _GON_ROT @ np.array((0.0, -0.506 * hl + 0.02, 0.0)), (it, it / 2, it), _GON_ROT
    )
    # Winter: forearm 0.016 M, centre of mass 0.430 of elbow -> wrist, radius of gyration 0.303;
    # the radius taken as half the forearm's mass along the model's radius (wrist at 0.2313 m);
    # about its long axis a tenth of the transverse inertia (assumed).
    fl, fm = 0.2313, 0.5 * 0.016 * body_mass
    itf = fm * (0.303 * fl) ** 2
    radius = Inertial.principal(fm, (0.0, -0.430 * fl, 0.0), (itf, itf / 10, itf))
    ulna = Inertial.principal(fm, (0.0, -0.430 * fl, 0.0), (itf, itf / 10, itf))
    links = (
        Link("radius", "ulna", "pro_sup", _GON_PS_CENTRE, _GON_PS_AXIS, (-1.5707963, 1.5707963), radius),
        Link(
            "proximal_row",
            "radius",
            "flexion",
            tuple(_GON_PROX),
            tuple(_GON_ROT[:, 2]),
            (-1.22173048, 1.22173048),
            LINK,
        ),
        Link(
            "hand",
            "proximal_row",
            "deviation",
            tuple(_GON_DIST),
            tuple(_GON_ROT[:, 0]),
            (-0.436332, 0.610865),
            hand,
        ),
    )
    centre = np.array(_GON_PS_CENTRE) + _GON_ROTAXIS  # the wrist centre in the ulna at pro_sup 0
    elbow_axis = np.array((0.22604694, 0.19103995, 0.95519973))  # joint elbow's flexion axis
    # The model has no markers: landmarks placed by us — the epicondyles 30 mm either side of
    # the elbow centre (the ulna's origin) along its flexion axis, the styloids either side of
    # the wrist centre (radial +Z: the model stands in the anatomical, supinated pose), the
    # markers on the hand's dorsum in the wrist (rotaxis) frame.
    hand_pt = lambda p: tuple(float(v) for v in _GON_ROT @ np.array(p))  # noqa: E731
    points = {
        "lateral_epicondyle": ("ulna", tuple(float(v) for v in 0.03 * elbow_axis)),
        "medial_epicondyle": ("ulna", tuple(float(v) for v in -0.03 * elbow_axis)),
        "radial_styloid": ("ulna", tuple(float(v) for v in centre + (0.004, 0.012, 0.026))),
        "ulnar_styloid": ("ulna", tuple(float(v) for v in centre + (-0.006, 0.014, -0.021))),
        "forearm_dorsal": ("ulna", (-0.022, -0.075, 0.012)),
        "mc2_head": ("hand", hand_pt((-0.012, -0.064, 0.021))),
        "mc5_head": ("hand", hand_pt((-0.010, -0.058, -0.027))),
        "mc3_base": ("hand", hand_pt((-0.017, -0.012, 0.003))),
    }
    return WristModel(
        "gonzalez1997",
        "Gonzalez, Buchanan & Delp 1997 (OpenSim WristModel), masses after Winter 2009",
        ulna,
        links,
        (0.0, 0.0, 0.0),
        ("pro_sup", "flexion", "deviation"),
        points,
        arm_length=0.30 + 0.2313 + 0.02,  # humerus (not in the model: 0.30 m assumed) + radius
    )


MODELS = {"rajagopal2016": rajagopal2016, "gonzalez1997": gonzalez1997}


# --- placement in the lab and forward kinematics -----------------------------------------------


def isb_forearm(landmarks: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, float]:
    """The ISB forearm frame of the four landmarks (any frame's coordinates): y from the
    mid-styloids to the mid-epicondyles, x = y × (ulnar → radial styloid) (volar for a right
    arm), z = x × y; origin at the mid-styloids. Returns (rotation columns x y z, origin, the
    distance between the two midpoints)."""
    p = {k: np.asarray(v, float) for k, v in landmarks.items()}
    mid_sty = (p["radial_styloid"] + p["ulnar_styloid"]) / 2
    mid_epi = (p["lateral_epicondyle"] + p["medial_epicondyle"]) / 2
    y = mid_epi - mid_sty
    length = float(np.linalg.norm(y))
    y = y / length
    x = np.cross(y, p["radial_styloid"] - p["ulnar_styloid"])
    x /= np.linalg.norm(x)
    return np.column_stack([x, y, np.cross(x, y)]), mid_sty, length


def _landmarks(model: WristModel) -> dict[str, np.ndarray]:
    names = ("radial_styloid", "ulnar_styloid", "lateral_epicondyle", "medial_epicondyle")
    return {k: np.array(model.points[k][1]) for k in names}


def forearm_frame(model: WristModel) -> tuple[np.ndarray, np.ndarray]:
    """The ISB forearm frame in the ulna's frame, from the model's own landmarks
    (:func:`isb_forearm`). Returns (rotation columns x y z, origin)."""
    f, origin, _ = isb_forearm(_landmarks(model))
    return f, origin


def forearm_length(model: WristModel) -> float:
    """Mid-styloids to mid-epicondyles, m (what a lab measures with the landmarks)."""
    return isb_forearm(_landmarks(model))[2]


def ulna_in_lab(model: WristModel, shoulder_flexion: float) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the ulna in the lab (rotation, translation) with the forearm hanging from the
    exam's shoulder, elbow extended, its ISB frame mid-prone, turned by ``shoulder_flexion``."""
    c, s = math.cos(shoulder_flexion), math.sin(shoulder_flexion)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    r_lab_isb = rz @ FOREARM_IN_LAB
    wrist = np.array(SHOULDER_IN_LAB) + rz @ np.array((0.0, -model.arm_length, 0.0))
    r_ulna_isb, o_ulna = forearm_frame(model)
    r = r_lab_isb @ r_ulna_isb.T
    return r, wrist - r @ o_ulna


def body_poses(model: WristModel, q: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each body's pose in the ulna's frame at model coordinates ``q`` (one row): the chain in
    NumPy, for Jacobians and tests (the trials come from OpenSim's own kinematics)."""
    poses = {"ulna": (np.eye(3), np.zeros(3))}
    for lk, qi in zip(model.links, q, strict=True):
        r_p, t_p = poses[lk.parent]
        poses[lk.body] = (r_p @ axis_angle(np.array(lk.axis), float(qi)), t_p + r_p @ np.array(lk.centre))
    return poses


# --- OpenSim ----------------------------------------------------------------------------------


def build_osim(
    model: WristModel,
    shoulder_flexion: float,
    markers: dict[str, tuple[str, np.ndarray]],
    path: str,
) -> str:
    """Writes the OpenSim model of ``model`` at the shoulder pose with ``markers`` (name ->
    (body, point in the body's frame)) to ``path``, built with OpenSim's API; returns the path.
    Each rotation is a PinJoint whose offset frames' z is the link's axis."""
    import opensim as osim

    def vec(v) -> osim.Vec3:
        return osim.Vec3(float(v[0]), float(v[1]), float(v[2]))

    def inertia(i: Inertial) -> osim.Inertia:
        m = i.inertia
        return osim.Inertia(m[0, 0], m[1, 1], m[2, 2], m[0, 1], m[0, 2], m[1, 2])

    m = osim.Model()
    m.setName(f"exam_{model.name}")
    m.setGravity(vec(GRAVITY))
    bodies = {"ground": m.getGround()}
    ulna = osim.Body("ulna", model.ulna.mass, vec(model.ulna.com), inertia(model.ulna))
    m.addBody(ulna)
    bodies["ulna"] = ulna
    r, t = ulna_in_lab(model, shoulder_flexion)
    m.addJoint(
        osim.WeldJoint(
            "lab_ulna", m.getGround(), vec(t), vec(xyz_of(r)), ulna, vec((0, 0, 0)), vec((0, 0, 0))
        )
    )
    for lk in model.links:
        body = osim.Body(lk.body, lk.inertial.mass, vec(lk.inertial.com), inertia(lk.inertial))
        m.addBody(body)
        bodies[lk.body] = body
        # A pin turns about its offset frames' z: give both offset frames an orientation whose
        # z is the axis (so the child's frame has the parent's orientation at zero).
        a = np.array(lk.axis)
        b = np.cross(a, (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0))
        b /= np.linalg.norm(b)
        orient = vec(xyz_of(np.column_stack([b, np.cross(a, b), a])))
        joint = osim.PinJoint(
            f"{lk.parent}_{lk.body}", bodies[lk.parent], vec(lk.centre), orient, body, vec((0, 0, 0)), orient
        )
        coord = joint.upd_coordinates(0)
        coord.setName(lk.coordinate)
        coord.setRangeMin(lk.range[0])
        coord.setRangeMax(lk.range[1])
        coord.setDefaultValue(model.neutral[model.links.index(lk)])
        m.addJoint(joint)
    for name, (body, p) in markers.items():
        m.addMarker(osim.Marker(name, bodies[body], vec(p)))
    m.finalizeConnections()
    m.printToXML(path)
    return path
