"""A serial kinematic chain: the one robot model of calibration and diagnosis (`rrbc calibrate`, the `kinematic` test
of `rrbc diagnose`), read from a URDF (`models.urdf.load_urdf`) or built from a DH table (`Chain.from_dh`: the
`--robot ur5|ur10` case). Forward kinematics and both Jacobians are vectorised over poses.

Frames and units: positions in the chain's base frame, mm; revolute joint values in rad, prismatic in mm (a file's
columns are converted by `column_scale`: radians and metres as ROS publishes them, or degrees for the q1..q6
columns of the DH arms).

Structure. The joints from the base link to the tip link are folded so that only moving joints remain: moving joint
k (revolute, continuous or prismatic) has `origin` (4, 4), the fixed transform from the previous moving joint's frame
(the fixed joints in between composed with its own origin), and `axis` a_k (unit, in its frame). It is driven by one
input (an actuated joint: a column of the file) as v_k = multiplier · input + offset — (1, 0) for the input's own
joint, the URDF's `<mimic>` values for a mimic joint, whose master may lie off the chain. `tail` (4, 4) takes the last
moving joint's frame to the tip link; `tool` (3,) is a tool point in the tip link's frame (mm).

Forward kinematics, F_0 = I:

    G_k = F_(k-1) · origin_k · E_k(δ)        the joint's frame before its motion
    F_k = G_k · M_k(v_k + offset_k)           M: rotation about a_k (revolute) or translation along it (prismatic)
    p   = F_last · tail · (tool + δ_tool)

Parameters δ (the errors calibration identifies), named `<joint>.<what>`, in mm or rad:
- a revolute or continuous joint: `offset` (its zero offset, rad), two rotations of its origin about the directions
  perpendicular to a_k (`rx`, `ry`, `rz` naming the joint-frame axes when a_k is one of them, else `ru`, `rv`), and
  three position errors of its origin (`x`, `y`, `z`, mm);
- a prismatic joint: `offset` (mm along a_k), three rotations, two position errors perpendicular to a_k;
- `tool.x`, `tool.y`, `tool.z`: the tool point's error in the tip link's frame (mm).
E_k(δ) = [Rot(Σ δr_j d_j) | Σ δp_j d_j] in the joint's frame: a rotation about the axis itself would repeat the
offset (for a prismatic joint, a shift along the axis), so neither is a parameter.

Jacobians (p − o: from the joint frame's origin o = G_k's translation to the tool point, R = G_k's rotation, E its
error rotation Rot(φ), φ = Σ δr_j d_j plus any deflection): position error along d → R Eᵀ d (the position error is
applied before the error rotation); rotation about d → (R J_r(φ) d) × (p − o), J_r SO(3)'s right Jacobian (both are
R d at the nominal chain, φ = 0); revolute offset or motion → (R a) × (p − o); prismatic → R a. An input's column sums
the columns of the joints it drives, times their multipliers. Exact at any δ (calibration's steps need it away from
the nominal arm).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import skew

KINDS = ("revolute", "continuous", "prismatic")
_AXIS_NAMES = ("x", "y", "z")


def rotation(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotations (..., 3, 3) about unit `axes` (..., 3) or one axis (3,) by `angles` (...) rad (Rodrigues)."""
    c, s = np.cos(angles)[..., None, None], np.sin(angles)[..., None, None]
    if np.ndim(axes) == 1:  # one axis: I + sin K + (1 - cos) K², K its cross-product matrix
        k1, k2 = _axis_matrices(*np.asarray(axes, float).tolist())
        return _EYE + s * k1 + (1.0 - c) * k2
    a = np.broadcast_to(np.asarray(axes, float), np.shape(angles) + (3,))
    k = np.zeros(a.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = a[..., 2], -a[..., 1], a[..., 0]
    outer = a[..., :, None] * a[..., None, :]
    return c * np.eye(3) + s * k + (1.0 - c) * outer


_EYE = np.eye(3)
_EYE.setflags(write=False)


@functools.lru_cache(maxsize=256)
def _axis_matrices(x: float, y: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    """(K, K²) of axis (x, y, z): its cross-product matrix and that squared (a chain's few axes, built once)."""
    k1 = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    k2 = k1 @ k1
    for m in (k1, k2):
        m.setflags(write=False)
    return k1, k2


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b over axis -2 of (..., 3, M) arrays (broadcast): np.cross without its per-call overhead."""
    a0, a1, a2 = a[..., 0, :], a[..., 1, :], a[..., 2, :]
    b0, b1, b2 = b[..., 0, :], b[..., 1, :], b[..., 2, :]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=-2)


def _rotvec(v: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) of a rotation vector (3,) rad: I + sin θ/θ K + (1 − cos θ)/θ² K², K = [v]×."""
    x, y, z = np.asarray(v, float).tolist()
    angle = math.sqrt(x * x + y * y + z * z)
    if angle == 0.0:
        return np.eye(3)
    k1 = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + (math.sin(angle) / angle) * k1 + ((1.0 - math.cos(angle)) / angle**2) * (k1 @ k1)


def _rotvecs(v: np.ndarray) -> np.ndarray:
    """Rotations (N, 3, 3) of rotation vectors (N, 3) rad."""
    angle = np.linalg.norm(v, axis=1)
    safe = np.where(angle > 0, angle, 1.0)
    return rotation(v / safe[:, None], angle)


def _right_jacobian(v: np.ndarray) -> np.ndarray:
    """SO(3)'s right Jacobian (3, 3) or (N, 3, 3) of rotation vectors v (3,) or (N, 3) rad: exp(v + ε) =
    exp(v) exp(J_r(v) ε) to first order in ε. J_r = I − (1 − cos θ)/θ² K + (θ − sin θ)/θ³ K², K = [v]×, θ = |v|."""
    if np.ndim(v) == 1:  # one vector: scalars, not arrays
        theta1 = float(np.linalg.norm(v))
        if theta1 < 1e-4:  # the series' next terms are below 1e-17 there
            a1, b1 = 0.5 - theta1**2 / 24.0, 1.0 / 6.0 - theta1**2 / 120.0
        else:
            a1 = (1.0 - math.cos(theta1)) / theta1**2
            b1 = (theta1 - math.sin(theta1)) / theta1**3
        k1 = skew(v)
        return np.eye(3) - a1 * k1 + b1 * (k1 @ k1)
    theta = np.linalg.norm(v, axis=-1)[..., None, None]
    small = theta < 1e-4  # the series' next terms are below 1e-17 there
    t = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / t**3)
    k = skew(v)
    return np.eye(3) - a * k + b * (k @ k)


def _perpendicular(axis: np.ndarray) -> tuple[tuple[np.ndarray, str], tuple[np.ndarray, str]]:
    """Two unit directions perpendicular to `axis` with their names: the other coordinate axes when `axis` is one
    of x, y, z (within 1e-9), else an orthonormal pair named u, v."""
    k = int(np.argmax(np.abs(axis)))
    if abs(abs(axis[k]) - 1.0) < 1e-9:
        others = [j for j in range(3) if j != k]
        return tuple((np.eye(3)[j], _AXIS_NAMES[j]) for j in others)  # type: ignore[return-value]
    u = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    u /= np.linalg.norm(u)
    return (u, "u"), (np.cross(axis, u), "v")


@dataclass(frozen=True, eq=False)
class Input:
    """An actuated joint: a column of the measurement file. `kind` revolute, continuous or prismatic; `lower`,
    `upper` its limits in rad or mm (None: none); `column` the file's column name, `scale` file value × scale = rad
    or mm (1 for radians, 1000 for metres, π/180 for degrees), `unit` the file's unit ("rad", "m" or "deg")."""

    name: str
    kind: str
    lower: float | None
    upper: float | None
    column: str
    scale: float
    unit: str


@dataclass(frozen=True, eq=False)
class MovingJoint:
    """A moving joint of the folded chain (module docstring): origin (4, 4) mm from the previous moving joint's frame,
    unit axis (3,) in its own frame, driven by input `driver` as multiplier · input + offset (rad or mm)."""

    name: str
    kind: str
    origin: np.ndarray
    axis: np.ndarray
    driver: int
    multiplier: float = 1.0
    offset: float = 0.0

    @property
    def prismatic(self) -> bool:
        return self.kind == "prismatic"


@dataclass(frozen=True, eq=False)
class Chain:
    """A serial chain from `base` to `tip` (module docstring). `joints`: the moving joints, base to tip; `inputs`:
    the actuated joints whose values the chain needs (a mimic joint's master included); `tail` (4, 4): the last
    moving joint's frame to the tip link, mm; `tool` (3,): the tool point in the tip link's frame, mm; `name` and
    `source` say where it came from (a URDF file, or "ur5" / "ur10")."""

    name: str
    base: str
    tip: str
    joints: tuple[MovingJoint, ...]
    inputs: tuple[Input, ...]
    tail: np.ndarray
    tool: np.ndarray
    source: str
    #: (K, 4) per moving joint: the mass (kg) its joint carries up to the next moving joint (its segment: the
    #: links rigidly attached to it on the chain, from the URDF's `<inertial>`) and their centre of mass (mm) in the
    #: joint's frame after its motion (F_k). None: the model has no masses (a DH table).
    inertia: np.ndarray | None = None

    def __post_init__(self):
        if not self.joints:
            raise InputError(f"{self.source}: no moving joint between {self.base} and {self.tip}: nothing to calibrate")
        for name in ("tail", "tool"):
            v = np.array(getattr(self, name), float)
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    # -------------------------------------------------------------------------------------------- parameters
    @property
    def columns(self) -> tuple[str, ...]:
        """The measurement file's joint columns, in input order."""
        return tuple(i.column for i in self.inputs)

    def with_tool(self, tool_mm) -> Chain:
        """The same chain with tool point `tool_mm` (3,) in the tip link's frame, mm."""
        t = np.asarray(tool_mm, float).reshape(3)
        if not np.all(np.isfinite(t)):
            raise InputError("the tool point must be 3 finite numbers (mm)")
        return Chain(self.name, self.base, self.tip, self.joints, self.inputs, self.tail, t, self.source, self.inertia)

    def _directions(self) -> list[tuple[int, str, str, np.ndarray]]:
        """Per parameter: (joint index or -1 for the tool, kind "offset"/"rot"/"pos", name suffix, direction)."""
        return self._parameters[0]

    @functools.cached_property
    def _parameters(self) -> tuple[list[tuple[int, str, str, np.ndarray]], np.ndarray, np.ndarray, np.ndarray]:
        """(`_directions`, their directions (P, 3), whether each is a rotation (P,) bool, whether its Jacobian column
        is a moment arm (P,) bool: a rotation or a revolute joint's offset); computed once per chain."""
        out: list[tuple[int, str, str, np.ndarray]] = []
        for k, j in enumerate(self.joints):
            out.append((k, "offset", "offset", j.axis))
            perp = _perpendicular(j.axis)
            rots = perp if not j.prismatic else tuple((np.eye(3)[i], _AXIS_NAMES[i]) for i in range(3))
            poss = perp if j.prismatic else tuple((np.eye(3)[i], _AXIS_NAMES[i]) for i in range(3))
            out += [(k, "rot", "r" + n, d) for d, n in rots]
            out += [(k, "pos", n, d) for d, n in poss]
        out += [(-1, "pos", n, np.eye(3)[i]) for i, n in enumerate(_AXIS_NAMES)]
        directions = np.array([d for _, _, _, d in out], float)
        is_rot = np.array([kind == "rot" for _, kind, _, _ in out])
        arm = np.array([kind == "rot" or (kind == "offset" and not self.joints[k].prismatic) for k, kind, _, _ in out])
        for a in (directions, is_rot, arm):
            a.setflags(write=False)
        return out, directions, is_rot, arm

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(
            ("tool" if k < 0 else self.joints[k].name) + "." + suffix for k, _, suffix, _ in self._directions()
        )

    @property
    def angular(self) -> np.ndarray:
        """(P,) bool: the parameter is an angle (rad); the others are mm."""
        return np.array(
            [
                kind == "rot" or (kind == "offset" and not self.joints[k].prismatic)
                for k, kind, _, _ in self._directions()
            ]
        )

    @property
    def n_params(self) -> int:
        return 6 * len(self.joints) + 3

    def reach_mm(self) -> float:
        """A length scale of the arm: the sum of its origins' and tool's offsets (mm), at least 100."""
        lengths = [np.linalg.norm(j.origin[:3, 3]) for j in self.joints]
        return max(100.0, float(np.sum(lengths) + np.linalg.norm(self.tail[:3, 3] + self.tail[:3, :3] @ self.tool)))

    # -------------------------------------------------------------------------------------------- kinematics
    def _values(self, q: np.ndarray) -> np.ndarray:
        """Joint values (N, K) of the moving joints for inputs q (N, I)."""
        drv = np.array([j.driver for j in self.joints])
        mul = np.array([j.multiplier for j in self.joints])
        off = np.array([j.offset for j in self.joints])
        return q[:, drv] * mul + off

    def _check_q(self, q) -> np.ndarray:
        qa = np.asarray(q, float)
        if qa.ndim == 1:
            qa = qa[None]
        if qa.ndim != 2 or qa.shape[1] != len(self.inputs) or not np.all(np.isfinite(qa)):
            raise InputError(f"joint values must be finite, shape (N, {len(self.inputs)}), got {np.shape(q)}")
        return qa

    def kinematics(
        self, q, delta=None, jacobians: bool = True, dv=None, drot=None
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Tool points and Jacobians for inputs q (N, I) (rad or mm) with parameter errors `delta` (P,) (None: the
        nominal chain) and, per pose, deflections under load (`models.loads`): `dv` (N, K) added to the moving
        joints' values (rad or mm), `drot` (N, K, 3) rotation vectors (rad) of each joint's origin in its frame, as
        the rotation parameters are.

        Returns
        -------
        p : ndarray, (N, 3)
            The tool point, base frame, mm.
        d_params : ndarray, (N, 3, P) or None
            ∂p/∂δ in mm per parameter unit (mm or rad), in `param_names` order.
        d_inputs : ndarray, (N, 3, I) or None
            ∂p/∂input in mm per rad or mm.
        """
        qa = self._check_q(q)
        n = len(qa)
        _, directions, is_rot, arm = self._parameters
        d = np.zeros(self.n_params) if delta is None else np.asarray(delta, float).reshape(self.n_params)
        v = self._values(qa) + (0.0 if dv is None else np.asarray(dv, float))
        rot = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        pos = np.zeros((n, 3))
        frames = []  # per joint: (R of G_k (N,3,3), o of G_k (N,3)) before the motion
        for k, j in enumerate(self.joints):
            base = 6 * k
            sl = slice(base + 1, base + 6)
            w = d[sl][:, None] * directions[sl]
            rv, e_pos = w[is_rot[sl]].sum(axis=0), w[~is_rot[sl]].sum(axis=0)
            if drot is None or not np.any(drot[:, k]):
                e_rot = _rotvec(rv)
            else:
                rv = rv + drot[:, k]
                e_rot = _rotvecs(rv)
            o_rot = j.origin[:3, :3] @ e_rot
            o_pos = j.origin[:3, :3] @ e_pos + j.origin[:3, 3]
            pos = pos + rot @ o_pos
            rot = rot @ o_rot
            frames.append((rot, pos, e_rot, rv))
            value = v[:, k] + d[base]
            if j.prismatic:
                pos = pos + (rot @ j.axis) * value[:, None]
            else:
                rot = rot @ rotation(j.axis, value)
        tool = self.tool + d[-3:]
        p = pos + rot @ (self.tail[:3, :3] @ tool + self.tail[:3, 3])
        if not jacobians:
            return p, None, None
        n_joints = len(frames)
        d_params = np.empty((n, 3, self.n_params))
        if n_joints:  # every joint's six columns at once
            locals_ = []
            for k, (_, _, e_rot, rv) in enumerate(frames):
                sl = slice(6 * k, 6 * k + 6)
                local = directions[sl].T  # (3, 6) in G_k's frame; exact away from the nominal chain (docstring)
                if np.any(rv):
                    local = np.broadcast_to(local, np.shape(e_rot)[:-2] + (3, 6)).copy()
                    rots, poss = is_rot[sl], ~is_rot[sl]
                    poss[0] = False  # the offset's direction is the axis itself, in G_k's frame
                    local[..., rots] = _right_jacobian(rv) @ local[..., rots]
                    local[..., poss] = np.swapaxes(e_rot, -1, -2) @ local[..., poss]
                locals_.append(local if local.ndim == 3 else local[None])
            local_all = np.stack(np.broadcast_arrays(*locals_))  # (K, N or 1, 3, 6)
            world = np.stack([f[0] for f in frames]) @ local_all  # (K, N, 3, 6)
            lever = (p[None] - np.stack([f[1] for f in frames]))[..., None]  # (K, N, 3, 1)
            cols = np.where(arm[: 6 * n_joints].reshape(n_joints, 1, 1, 6), _cross(world, lever), world)
            d_params[:, :, : 6 * n_joints] = cols.transpose(1, 2, 0, 3).reshape(n, 3, 6 * n_joints)
        d_params[:, :, -3:] = rot @ (self.tail[:3, :3] @ directions[-3:].T)
        d_inputs = np.zeros((n, 3, len(self.inputs)))
        for k, j in enumerate(self.joints):
            d_inputs[:, :, j.driver] += j.multiplier * d_params[:, :, 6 * k]
        return p, d_params, d_inputs

    def joint_error(self, k: int, delta) -> np.ndarray:
        """(4, 4) mm: moving joint k's identified error as `kinematics` applies it after the joint's folded origin,
        E_k(δ) · M_k(δ_offset) (module docstring; the offset as a motion about or along the joint's own axis, which
        commutes with the joint's motion). `delta` (P,) in `param_names` order."""
        d = np.asarray(delta, float).reshape(self.n_params)
        dirs = self._directions()
        rv, pos = np.zeros(3), np.zeros(3)
        for idx in range(6 * k + 1, 6 * k + 6):
            if dirs[idx][1] == "rot":
                rv = rv + d[idx] * dirs[idx][3]
            else:
                pos = pos + d[idx] * dirs[idx][3]
        e = np.eye(4)
        e[:3, :3], e[:3, 3] = _rotvec(rv), pos
        j = self.joints[k]
        m = np.eye(4)
        if j.prismatic:
            m[:3, 3] = j.axis * d[6 * k]
        else:
            m[:3, :3] = rotation(j.axis, np.array(d[6 * k]))
        return e @ m

    def forward(self, q, delta=None) -> np.ndarray:
        """Tool points (N, 3), base frame, mm, for inputs q (N, I) rad or mm (`kinematics` without Jacobians)."""
        return self.kinematics(q, delta, jacobians=False)[0]

    def frames(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The nominal chain's joint frames at inputs q (N, I), base frame: before each joint's motion (G_k: rotations
        (N, K, 3, 3), origins (N, K, 3) mm) and after it (F_k: the same shapes)."""
        qa = self._check_q(q)
        n, kk = len(qa), len(self.joints)
        v = self._values(qa)
        g_rot, g_pos = np.empty((n, kk, 3, 3)), np.empty((n, kk, 3))
        f_rot, f_pos = np.empty((n, kk, 3, 3)), np.empty((n, kk, 3))
        rot = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        pos = np.zeros((n, 3))
        for k, j in enumerate(self.joints):
            pos = pos + rot @ j.origin[:3, 3]
            rot = rot @ j.origin[:3, :3]
            g_rot[:, k], g_pos[:, k] = rot, pos
            if j.prismatic:
                pos = pos + (rot @ j.axis) * v[:, k, None]
            else:
                rot = rot @ rotation(j.axis, v[:, k])
            f_rot[:, k], f_pos[:, k] = rot, pos
        return g_rot, g_pos, f_rot, f_pos

    # -------------------------------------------------------------------------------------------- from DH
    @classmethod
    def from_dh(cls, dh, name: str, tool_mm=None) -> Chain:
        """The chain of a standard-DH six-joint arm (`models.kinematics.DHParameters`): joint i turns about z by
        q_i + theta_offset_i, then Tz(d_i) Tx(a_i) Rx(alpha_i) leads to joint i + 1 (the last one to the flange).
        Inputs are the file's columns q1..q6 in degrees; the tool point defaults to the DH table's tool length
        along the flange's z axis."""

        def link(i: int) -> np.ndarray:
            m = np.eye(4)
            m[:3, :3] = rotation(np.array([0.0, 0.0, 1.0]), np.array(dh.theta_offset[i]))
            step = np.eye(4)
            step[:3, :3] = rotation(np.array([1.0, 0.0, 0.0]), np.array(dh.alpha[i]))
            step[:3, 3] = [dh.a[i], 0.0, dh.d[i]]
            # Rz(θ) Tz(d) Tx(a) Rx(α) = Rz(θ) · [Rx(α) | (a, 0, d)]
            return m @ step

        z = np.array([0.0, 0.0, 1.0])
        joints = tuple(
            MovingJoint(f"joint{i + 1}", "revolute", np.eye(4) if i == 0 else link(i - 1), z, i) for i in range(6)
        )
        inputs = tuple(
            Input(f"joint{i + 1}", "revolute", -2 * np.pi, 2 * np.pi, f"q{i + 1}", np.pi / 180.0, "deg")
            for i in range(6)
        )
        tool = np.array([0.0, 0.0, dh.tool_mm]) if tool_mm is None else np.asarray(tool_mm, float)
        return cls(name, "base", "flange", joints, inputs, link(5), tool, name)
