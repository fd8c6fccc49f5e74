"""The views' poses from all their pairs at once: a pose graph (Open3D's global optimisation).

Each accepted pair is an edge with its ICP transform and information matrix; a view's pose maps
its world frame into the reference frame (the first view's). The graph starts from a spanning
tree of the best-overlapping pairs and is adjusted over every pair, so that a loop of views
closes. What the loop did before and after is measured: ``loop_closure`` composes the pairs'
transforms around the views in order (view 0 → 1 → … → 0) and gives how far that is from the
identity; ``residuals`` each pair's transform against the adjusted poses.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gnomon.fuse.o3d import open3d
from gnomon.fuse.registration import PairRegistration, rotation_angle_deg

__all__ = ["EdgeResidual", "spanning_poses", "optimise_poses", "edge_residual", "loop_closure"]


@dataclass
class EdgeResidual:
    """How far a pair's own transform is from the poses: rotation (degrees) and the displacement
    (world units) of the pair's object points' centre."""

    source: int
    target: int
    rotation_deg: float
    displacement: float


def spanning_poses(n: int, pairs: dict[tuple[int, int], PairRegistration],
                   score: Callable[[int, np.ndarray, list[int], list[np.ndarray]], float],
                   ) -> tuple[list[np.ndarray], list[int]]:
    """Poses (view → view 0) along a spanning tree grown from view 0: at each step, of every pair
    joining a placed view to one not yet placed, the one whose pose for the new view ``score``s best
    (``score(view, pose, placed views, their poses)``: how well the view agrees with all placed views,
    not only with the pair's partner, so that a pair aligned the wrong way round is not followed);
    and the views no pair reaches."""
    poses: list[np.ndarray | None] = [None] * n
    poses[0] = np.eye(4)
    while True:
        placed = [k for k in range(n) if poses[k] is not None]
        known = [P for P in poses if P is not None]
        best = None
        for (i, j), p in pairs.items():
            for a, b, T in ((i, j, p.transform), (j, i, np.linalg.inv(p.transform))):
                # a → b by T; b placed, a not: pose_a = pose_b · T
                pb = poses[b]
                if pb is not None and poses[a] is None:
                    candidate = pb @ T
                    value = score(a, candidate, placed, known)
                    if best is None or value > best[0]:
                        best = (value, a, candidate)
        if best is None:
            break
        poses[best[1]] = best[2]
    missing = [k for k, P in enumerate(poses) if P is None]
    return [np.eye(4) if P is None else P for P in poses], missing


def optimise_poses(poses: list[np.ndarray], pairs: dict[tuple[int, int], PairRegistration]) -> list[np.ndarray]:
    """Open3D's global optimisation (Levenberg–Marquardt) of the poses over every pair, view 0 held."""
    o3d = open3d()
    reg = o3d.pipelines.registration
    graph = reg.PoseGraph()
    for P in poses:
        graph.nodes.append(reg.PoseGraphNode(P))
    for (i, j), p in pairs.items():
        graph.edges.append(reg.PoseGraphEdge(i, j, p.transform, p.information, uncertain=False))
    option = reg.GlobalOptimizationOption(max_correspondence_distance=1.0, edge_prune_threshold=0.25,
                                          preference_loop_closure=1.0, reference_node=0)
    reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                            reg.GlobalOptimizationConvergenceCriteria(), option)
    out = [np.asarray(node.pose).copy() for node in graph.nodes]
    ref = np.linalg.inv(out[0])
    return [ref @ P for P in out]


def edge_residual(i: int, j: int, T_ij: np.ndarray, poses: list[np.ndarray], centre: np.ndarray) -> EdgeResidual:
    """The pair (i → j)'s transform against the poses, at ``centre`` (view i's frame)."""
    E = np.linalg.inv(poses[j]) @ poses[i] @ np.linalg.inv(T_ij)
    c = T_ij[:3, :3] @ centre + T_ij[:3, 3]
    moved = E[:3, :3] @ c + E[:3, 3] - c
    return EdgeResidual(i, j, rotation_angle_deg(E), float(np.linalg.norm(moved)))


def loop_closure(n: int, pairs: dict[tuple[int, int], PairRegistration], centre: np.ndarray) -> dict | None:
    """The pairs' transforms composed around the views in order, 0 → 1 → … → n−1 → 0: the rotation
    (degrees) and displacement (world units, at ``centre`` in view 0's frame) left; None when a pair of
    the loop was not accepted."""
    T = np.eye(4)
    for k in range(n):
        a, b = k, (k + 1) % n
        if (a, b) in pairs:
            step = pairs[(a, b)].transform
        elif (b, a) in pairs:
            step = np.linalg.inv(pairs[(b, a)].transform)
        else:
            return None
        T = step @ T
    moved = T[:3, :3] @ centre + T[:3, 3] - centre
    return {"views": list(range(n)) + [0], "rotation_deg": rotation_angle_deg(T),
            "displacement": float(np.linalg.norm(moved))}
