"""The parking lot's geometry and the scripted expert's path (plain numpy; no simulator import).

The layout is highway-env's ``ParkingEnv._create_road``: ``n_spots`` spots of
4 m x 8 m side by side in two rows facing each other across a 20 m aisle.
Spot ``k < n_spots`` is in the row at ``y > 0`` (entered heading +y), spot
``n_spots + k`` opposite it (entered heading -y), both at
``x = (k + 1 - n_spots // 2) * 4 - 2``; a spot's target is its centre, 14 m
from the aisle's centre line, with the spot's heading (the order of
``road.network.lanes_list()``, which gr_envs indexes goals by).

The expert's path is the shortest path of bounded curvature (Dubins) from the
start pose to a pre-spot pose in line with the spot, :data:`RUN_IN` metres
before its centre, then straight in. Of the six Dubins words, the shortest
one that keeps the car :data:`MARGIN` metres inside the lot's walls is taken.
"""

from __future__ import annotations

import math

import numpy as np

Pose = tuple[float, float, float]  # x, y (metres), heading (radians)

SPOT_WIDTH, SPOT_LENGTH, AISLE = 4.0, 8.0, 10.0  # highway-env's width, length and y_offset
WALLS = (35.0, 21.0)  # half width and half height of highway-env's walls (70 m x 42 m)
MARGIN = 3.5  # metres the path keeps from the walls: half the car's length (5 m) and a metre to spare
RADIUS = 7.0  # turning radius of the path (the car's tightest, at full steer, is 5.6 m)
RUN_IN = 10.0  # straight run into the spot, from 4 m outside its entrance to its centre
STEP = 0.25  # spacing of the path's points (metres)


def spot_pose(spot: int, n_spots: int) -> Pose:
    """Centre and heading of spot ``spot`` (0 <= spot < 2 * n_spots)."""
    k, row = spot % n_spots, spot // n_spots
    x = (k + 1 - n_spots // 2) * SPOT_WIDTH - SPOT_WIDTH / 2
    sign = 1.0 if row == 0 else -1.0
    return x, sign * (AISLE + SPOT_LENGTH / 2), sign * math.pi / 2


def _mod(angle: float) -> float:
    return angle % (2 * math.pi)


def _words(alpha: float, beta: float, d: float) -> dict[str, tuple[float, float, float]]:
    """Segment lengths (in radii) of the Dubins words feasible between two normalised poses."""
    sa, sb, ca, cb = math.sin(alpha), math.sin(beta), math.cos(alpha), math.cos(beta)
    cab = math.cos(alpha - beta)
    out = {}
    p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
    if p2 >= 0:
        t1 = math.atan2(cb - ca, d + sa - sb)
        out["LSL"] = (_mod(-alpha + t1), math.sqrt(p2), _mod(beta - t1))
    p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
    if p2 >= 0:
        t1 = math.atan2(ca - cb, d - sa + sb)
        out["RSR"] = (_mod(alpha - t1), math.sqrt(p2), _mod(-beta + t1))
    p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        t2 = math.atan2(-ca - cb, d + sa + sb) - math.atan2(-2.0, p)
        out["LSR"] = (_mod(-alpha + t2), p, _mod(-_mod(beta) + t2))
    p2 = d * d - 2 + 2 * cab - 2 * d * (sa + sb)
    if p2 >= 0:
        p = math.sqrt(p2)
        t2 = math.atan2(ca + cb, d - sa - sb) - math.atan2(2.0, p)
        out["RSL"] = (_mod(alpha - t2), p, _mod(beta - t2))
    c = (6 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8
    if abs(c) <= 1:
        p = _mod(2 * math.pi - math.acos(c))
        t = _mod(alpha - math.atan2(ca - cb, d - sa + sb) + p / 2)
        out["RLR"] = (t, p, _mod(alpha - beta - t + p))
    c = (6 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8
    if abs(c) <= 1:
        p = _mod(2 * math.pi - math.acos(c))
        t = _mod(-alpha - math.atan2(ca - cb, d + sa - sb) + p / 2)
        out["LRL"] = (t, p, _mod(beta - alpha - t + p))
    return out


def _trace(start: Pose, word: str, lengths: tuple[float, ...], radius: float) -> np.ndarray:
    """Points ``(x, y, heading)`` every :data:`STEP` metres along a Dubins word."""
    x, y, h = start
    points = [(x, y, h)]
    for kind, length in zip(word, lengths):
        total = length * radius
        n = max(1, math.ceil(total / STEP))
        ds = total / n
        k = {"L": 1.0 / radius, "R": -1.0 / radius, "S": 0.0}[kind]
        for _ in range(n):
            if k == 0.0:
                x, y = x + ds * math.cos(h), y + ds * math.sin(h)
            else:
                h2 = h + k * ds
                x, y = x + (math.sin(h2) - math.sin(h)) / k, y + (math.cos(h) - math.cos(h2)) / k
                h = h2
            points.append((x, y, h))
    return np.array(points)


def _inside(points: np.ndarray, margin: float) -> bool:
    return bool(np.all(np.abs(points[:, 0]) <= WALLS[0] - margin) and np.all(np.abs(points[:, 1]) <= WALLS[1] - margin))


def dubins(start: Pose, end: Pose, radius: float = RADIUS, margin: float = MARGIN) -> np.ndarray:
    """The shortest Dubins path from ``start`` to ``end`` staying ``margin`` inside the walls, as points.

    Raises:
        ValueError: If no Dubins word stays inside.
    """
    dx, dy = end[0] - start[0], end[1] - start[1]
    theta = _mod(math.atan2(dy, dx))
    alpha, beta = _mod(start[2] - theta), _mod(end[2] - theta)
    best = None
    for word, lengths in sorted(_words(alpha, beta, math.hypot(dx, dy) / radius).items(), key=lambda w: sum(w[1])):
        points = _trace(start, word, lengths, radius)
        if math.dist(points[-1, :2], end[:2]) > 1e-6 * radius + 1e-6 or not _inside(points, margin):
            continue
        best = points
        break
    if best is None:
        raise ValueError(f"no path of radius {radius} from {start} to {end} stays inside the walls")
    return best


def expert_path(start: Pose, spot: int, n_spots: int) -> np.ndarray:
    """The expert's path to ``spot``: Dubins to the pre-spot pose, then straight to the spot's centre.

    Returns:
        ``(N, 3)`` points ``(x, y, heading)``, the spot's centre last.
    """
    x, y, heading = spot_pose(spot, n_spots)
    pre = (x - RUN_IN * math.cos(heading), y - RUN_IN * math.sin(heading), heading)
    approach = dubins(start, pre)
    n = math.ceil(RUN_IN / STEP)
    run_in = np.array([(pre[0] + s * math.cos(heading), pre[1] + s * math.sin(heading), heading)
                       for s in np.linspace(0.0, RUN_IN, n + 1)[1:]])
    return np.vstack([approach, run_in])
