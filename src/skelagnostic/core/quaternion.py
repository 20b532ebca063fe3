"""Quaternion helpers in the (w, x, y, z) convention.

Every function takes tensors with arbitrary leading batch dimensions and keeps
the input dtype and device. The storage convention of skelagnostic is
**(w, x, y, z)** (scalar first), as in BVH tooling and the papers; ``roma``, which
does the Euler and matrix conversions here, is (x, y, z, w), so the conversion
happens at this boundary and nowhere else. roma is imported lazily: importing it
pulls in ``torch._dynamo``, which costs seconds.

Products, inverses and rotations of vectors are written out with plain tensor
arithmetic: they are one fused expression each and measurably faster in the
forward-kinematics loop than round-tripping through ``roma``'s (x, y, z, w)
layout (see ``benchmarks/``).
"""

from __future__ import annotations

import torch

__all__ = [
    "best_rotation",
    "continuity",
    "euler_to_quat",
    "from_matrix",
    "from_rot6d",
    "from_rotvec",
    "identity",
    "inv",
    "mul",
    "normalize",
    "quat_to_euler",
    "rotate",
    "rotation_between",
    "slerp",
    "to_matrix",
    "to_rot6d",
    "to_rotvec",
    "yaw",
]

_EULER_ORDERS = {"".join(p) for p in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")}


def identity(*shape: int, dtype: torch.dtype = torch.float32, device=None) -> torch.Tensor:
    """Identity quaternions (1, 0, 0, 0) of shape ``[*shape, 4]``."""
    q = torch.zeros(*shape, 4, dtype=dtype, device=device)
    q[..., 0] = 1.0
    return q


def mul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a * b`` of (w, x, y, z) quaternions (broadcasting)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        dim=-1,
    )


def inv(q: torch.Tensor) -> torch.Tensor:
    """Inverse of unit (w, x, y, z) quaternions (the conjugate)."""
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def normalize(q: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Scale quaternions to unit norm (guarded against zero norm)."""
    return q / q.norm(dim=-1, keepdim=True).clamp_min(eps)


def rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate 3-vectors ``v`` by unit (w, x, y, z) quaternions ``q`` (broadcasting).

    Uses ``v' = v + 2 w (u x v) + 2 u x (u x v)`` with ``u`` the vector part.
    Mixed precisions (e.g. float32 rotations of bfloat16 vectors under autocast) are
    computed in the wider of the two.
    """
    dtype = torch.promote_types(q.dtype, v.dtype)
    q, v = q.to(dtype), v.to(dtype)
    shape = torch.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    w = q[..., :1]
    u = q[..., 1:].expand(*shape, 3)
    v = v.expand(*shape, 3)
    t = 2.0 * torch.linalg.cross(u, v, dim=-1)
    return v + w * t + torch.linalg.cross(u, t, dim=-1)


def to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Unit (w, x, y, z) quaternions ``[..., 4]`` to rotation matrices ``[..., 3, 3]``."""
    w, x, y, z = q.unbind(-1)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = (
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    )  # fmt: skip
    return torch.stack(rows, dim=-1).reshape(*q.shape[:-1], 3, 3)


def from_matrix(m: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``[..., 3, 3]`` to unit (w, x, y, z) quaternions with ``w >= 0``."""
    import roma

    q = roma.quat_xyzw_to_wxyz(roma.rotmat_to_unitquat(m))
    return torch.where(q[..., :1] < 0, -q, q)


def to_rot6d(q: torch.Tensor) -> torch.Tensor:
    """Unit (w, x, y, z) quaternions ``[..., 4]`` to 6D rotations ``[..., 6]`` (Zhou et al. 2019).

    The 6D layout is the first two columns of the rotation matrix ``m``, column
    after column: ``(m00, m10, m20, m01, m11, m21)``.
    """
    return to_matrix(q)[..., :2].transpose(-1, -2).reshape(*q.shape[:-1], 6)


def from_rot6d(x: torch.Tensor) -> torch.Tensor:
    """6D rotations ``[..., 6]`` (any two non-parallel columns) to unit (w, x, y, z) quaternions.

    The two columns are orthonormalised by Gram-Schmidt
    (``roma.special_gramschmidt``), so a network's raw 6D output decodes to a
    rotation; the third column is their cross product. ``w >= 0``.
    """
    import roma

    columns = x.reshape(*x.shape[:-1], 2, 3).transpose(-1, -2)
    return from_matrix(roma.special_gramschmidt(columns))


def to_rotvec(q: torch.Tensor) -> torch.Tensor:
    """Unit (w, x, y, z) quaternions ``[..., 4]`` to rotation vectors ``[..., 3]`` (axis * angle).

    The angle is in ``[0, pi]`` (the shorter arc; ``roma.unitquat_to_rotvec``),
    so ``q`` and ``-q`` give the same vector; near ``pi`` the vector flips to the
    opposite axis.
    """
    import roma

    return roma.unitquat_to_rotvec(roma.quat_wxyz_to_xyzw(q))


def from_rotvec(v: torch.Tensor) -> torch.Tensor:
    """Rotation vectors ``[..., 3]`` (axis * angle, radians) to unit (w, x, y, z) quaternions."""
    import roma

    return roma.quat_xyzw_to_wxyz(roma.rotvec_to_unitquat(v))


def _unit(v: torch.Tensor, eps: float = 1e-9) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(eps)


def rotation_between(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Shortest-arc rotations taking directions ``u`` to directions ``v``.

    Args:
        u: ``[..., 3]`` source directions (any length; zero gives identity).
        v: ``[..., 3]`` target directions (broadcastable with ``u``).

    Returns:
        ``[..., 4]`` unit quaternions (w, x, y, z); opposite directions turn by
        pi about an axis perpendicular to ``u``.

    Example:
        >>> q = rotation_between(torch.tensor([1.0, 0, 0]), torch.tensor([0.0, 2, 0]))
        >>> rotate(q, torch.tensor([1.0, 0, 0])).round(decimals=6).tolist()
        [0.0, 1.0, 0.0]
    """
    u, v = torch.broadcast_tensors(_unit(u), _unit(v))
    w = 1.0 + (u * v).sum(-1, keepdim=True)
    xyz = torch.linalg.cross(u, v, dim=-1)
    nonzero = (u.norm(dim=-1, keepdim=True) > 0.5) & (v.norm(dim=-1, keepdim=True) > 0.5)
    opposite = (w < 1e-7) & nonzero
    if bool(opposite.any()):
        ex = torch.zeros_like(u)
        ex[..., 0] = 1.0
        ey = torch.zeros_like(u)
        ey[..., 1] = 1.0
        helper = torch.where(u[..., :1].abs() < 0.9, ex, ey)
        axis = _unit(torch.linalg.cross(u, helper, dim=-1))
        w = torch.where(opposite, torch.zeros_like(w), w)
        xyz = torch.where(opposite, axis, xyz)
    w = torch.where(nonzero, w, torch.ones_like(w))
    xyz = torch.where(nonzero, xyz, torch.zeros_like(xyz))
    return normalize(torch.cat([w, xyz], dim=-1))


def best_rotation(
    source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """The rotation that best maps vectors ``source`` onto ``target`` (Kabsch), as a quaternion.

    Minimises ``sum_k w_k ||R source_k - target_k||^2`` over rotations ``R``
    (``roma.rigid_vectors_registration``: the SVD solution with the sign fix
    that keeps ``det R = +1``). Unique when the vectors span a plane; with
    collinear vectors the turn about their line is arbitrary.

    Args:
        source: ``[..., K, 3]`` vectors.
        target: ``[..., K, 3]`` vectors (broadcastable with ``source``).
        weights: Optional ``[..., K]`` positive weights (default: equal).

    Returns:
        ``[..., 4]`` unit quaternions (w, x, y, z) with ``w >= 0``.

    Example:
        >>> x = torch.tensor([[1.0, 0, 0], [0, 1, 0]])
        >>> q = best_rotation(x, torch.tensor([[0.0, 1, 0], [-1, 0, 0]]))
        >>> rotate(q, x).round(decimals=6).tolist()
        [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
    """
    import roma

    source, target = torch.broadcast_tensors(source, target)
    return from_matrix(roma.rigid_vectors_registration(source, target, weights))


def _check_order(order: str) -> str:
    order = order.upper()
    if order not in _EULER_ORDERS:
        raise ValueError(f"Euler order must be a permutation of 'XYZ', got {order!r}")
    return order


def euler_to_quat(angles: torch.Tensor, order: str, degrees: bool = True) -> torch.Tensor:
    """Intrinsic Euler angles to unit (w, x, y, z) quaternions.

    BVH semantics: channels ``Zrotation Xrotation Yrotation`` with values
    ``(a, b, c)`` mean ``R = Rz(a) @ Rx(b) @ Ry(c)``, i.e. ``order="ZXY"`` with
    ``angles[..., 0]`` the Z angle. One to three axes are accepted (BVH joints may
    declare fewer than three rotation channels).

    Written out as a product of per-axis quaternions rather than through
    ``roma.euler_to_unitquat``, whose generic rotation-vector path dominated BVH
    reading in profiles; the two agree to 1e-15 (the tests compare with scipy).

    Args:
        angles: ``[..., D]`` angles, in the order given by ``order`` (D = ``len(order)``).
        order: Axis letters, e.g. ``"ZXY"`` (intrinsic rotations).
        degrees: Whether the angles are in degrees (BVH) or radians.

    Returns:
        ``[..., 4]`` unit quaternions.
    """
    order = order.upper()
    if not order or len(order) > 3 or len(set(order)) != len(order) or set(order) - set("XYZ"):
        raise ValueError(f"Euler order must be a permutation of 'XYZ', got {order!r}")
    if angles.shape[-1] != len(order):
        raise ValueError(f"{len(order)} Euler axes {order!r} but angles end in {angles.shape[-1]}")
    rad = torch.deg2rad(angles) if degrees else angles
    # component-wise product of the per-axis quaternions, on contiguous tensors
    half = (0.5 * rad).movedim(-1, 0).contiguous()
    cos, sin = torch.cos(half), torch.sin(half)
    w = cos[0]
    v = [torch.zeros_like(w), torch.zeros_like(w), torch.zeros_like(w)]
    v["XYZ".index(order[0])] = sin[0]
    for i in range(1, len(order)):
        # (w, v) * (c, s e_k) = (w c - s v_k, c v + s w e_k + s v x e_k)
        c, sn, k = cos[i], sin[i], "XYZ".index(order[i])
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        new_w = w * c - sn * v[k]
        new_v = list(v)
        new_v[k] = v[k] * c + sn * w
        new_v[k1] = v[k1] * c + sn * v[k2]
        new_v[k2] = v[k2] * c - sn * v[k1]
        w, v = new_w, new_v
    return torch.stack((w, v[0], v[1], v[2]), dim=-1)


def quat_to_euler(q: torch.Tensor, order: str, degrees: bool = True) -> torch.Tensor:
    """Unit (w, x, y, z) quaternions to intrinsic Euler angles (inverse of :func:`euler_to_quat`).

    The middle angle lies in [-90, 90] degrees, the others in (-180, 180]. Closed-form
    on the rotation matrix; rows within 1e-6 of gimbal lock are delegated to
    ``roma.unitquat_to_euler``, which picks a valid decomposition there.

    Args:
        q: ``[..., 4]`` unit quaternions.
        order: Three axis letters, e.g. ``"ZYX"``.
        degrees: Return degrees (default) or radians.

    Returns:
        ``[..., 3]`` angles in the order of ``order``.
    """
    order = _check_order(order)
    i, j, k = ("XYZ".index(c) for c in order)
    sign = 1.0 if order in {"XYZ", "YZX", "ZXY"} else -1.0
    m = to_matrix(q)
    sin_mid = (sign * m[..., i, k]).clamp(-1.0, 1.0)
    out = torch.stack(
        (
            torch.atan2(-sign * m[..., j, k], m[..., k, k]),
            torch.asin(sin_mid),
            torch.atan2(-sign * m[..., i, j], m[..., i, i]),
        ),
        dim=-1,
    )
    locked = sin_mid.abs() > 1.0 - 1e-6
    if bool(locked.any()):
        import roma

        out[locked] = roma.unitquat_to_euler(order, roma.quat_wxyz_to_xyzw(q[locked])).to(out)
    return torch.rad2deg(out) if degrees else out


def continuity(q: torch.Tensor, dim: int = -3) -> torch.Tensor:
    """Remove sign flips along ``dim`` (``q`` and ``-q`` are the same rotation).

    Each quaternion is negated when its dot product with the previous one (after
    fixing) is negative, so consecutive frames lie on the same hemisphere. With
    the usual ``[T, J, 4]`` layout the time axis is ``dim=-3``.
    """
    dim = dim % q.dim()
    if dim == q.dim() - 1:
        raise ValueError("continuity: dim must not be the quaternion axis")
    qt = q.movedim(dim, 0)
    if qt.shape[0] < 2:
        return q.clone()
    dots = (qt[1:] * qt[:-1]).sum(-1)
    flips = (dots < 0).to(torch.int64)
    parity = torch.cumsum(flips, dim=0) % 2
    sign = torch.ones_like(qt[..., 0])
    sign[1:] = 1.0 - 2.0 * parity.to(q.dtype)
    return (qt * sign.unsqueeze(-1)).movedim(0, dim)


def slerp(a: torch.Tensor, b: torch.Tensor, t: torch.Tensor | float) -> torch.Tensor:
    """Spherical linear interpolation between unit quaternions along the shorter arc.

    Args:
        a: ``[..., 4]`` start quaternions.
        b: ``[..., 4]`` end quaternions (broadcastable with ``a``).
        t: Interpolation weights in [0, 1], broadcastable to ``a[..., 0]``.

    Returns:
        ``[..., 4]`` unit quaternions.
    """
    t = torch.as_tensor(t, dtype=a.dtype, device=a.device)
    dot = (a * b).sum(-1)
    b = torch.where((dot < 0).unsqueeze(-1), -b, b)
    dot = dot.abs().clamp(max=1.0)
    theta = torch.acos(dot)
    sin_theta = torch.sin(theta)
    near = sin_theta < 1e-6
    safe = torch.where(near, torch.ones_like(sin_theta), sin_theta)
    wa = torch.where(near, 1.0 - t, torch.sin((1.0 - t) * theta) / safe)
    wb = torch.where(near, t, torch.sin(t * theta) / safe)
    return normalize(wa.unsqueeze(-1) * a + wb.unsqueeze(-1) * b)


def yaw(q: torch.Tensor, up: int = 1, forward: int = 2) -> torch.Tensor:
    """Heading-only part of rotations, as a rotation about the ``up`` axis.

    The result maps the ``forward`` axis onto its rotated, ground-projected direction.

    Args:
        q: ``[..., 4]`` unit quaternions.
        up: Index (0, 1, 2) of the up axis.
        forward: Index of the rest forward axis.

    Returns:
        ``[..., 4]`` unit quaternions rotating about the up axis only.
    """
    f = torch.zeros(*q.shape[:-1], 3, dtype=q.dtype, device=q.device)
    f[..., forward] = 1.0
    return heading_from_direction(rotate(q, f), up=up, forward=forward)


def heading_from_direction(d: torch.Tensor, up: int = 1, forward: int = 2) -> torch.Tensor:
    """Rotation about the ``up`` axis that maps the ``forward`` axis onto ``d`` on the ground.

    ``d`` need not be normalised; only its ground projection counts.
    """
    lateral = 3 - up - forward
    # angle about `up` from forward to d, measured with the right-hand rule.
    # For Y-up, Z-forward: rotating Z towards X is positive about Y.
    sign = 1.0 if (up, forward, lateral) in {(1, 2, 0), (2, 0, 1), (0, 1, 2)} else -1.0
    angle = torch.atan2(sign * d[..., lateral], d[..., forward])
    half = 0.5 * angle
    out = torch.zeros(*d.shape[:-1], 4, dtype=d.dtype, device=d.device)
    out[..., 0] = torch.cos(half)
    out[..., 1 + up] = torch.sin(half)
    return out
