"""Pairwise FPFH + RANSAC + ICP registration, the pre-merge (paper 3: scans with more than 60 %
alignment inliers become one fragment) and the FPFH chaining baseline (paper Table 1).

Transforms are (4, 4) float64 acting on column vectors, ``x_target = T @ [x_source, 1]``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from schemas.params import RegistrationParams
from services.manhattan import voxel_thin
from services.types import FloatArray

__all__ = [
    "MergedGroup",
    "PairKey",
    "PairRegistration",
    "PremergeResult",
    "chain_baseline",
    "premerge",
    "register_all",
    "register_pair",
]

_reg = o3d.pipelines.registration
PairKey = tuple[str, str]  # (a, b), a before b in input order
_Clouds = Mapping[str, FloatArray]
_Poses = dict[str, FloatArray]
_MIN_POINTS = 10  # fewer downsampled points than this: registration is not attempted


@dataclass(frozen=True)
class PairRegistration:
    """Result of registering one fragment onto another.

    transform: (4, 4) float64, maps source-local -> target-local.
    inlier_ratio: share of the smaller downsampled cloud's points with a partner within
    ``icp_distance_factor * voxel_size`` after alignment (the paper's "alignment inliers").
    0.0 when registration was not possible (too few points); transform is then identity.
    rmse: RMS distance of those inlier pairs, m (inf when there are none).
    """

    transform: FloatArray
    inlier_ratio: float
    rmse: float


_Pairs = Mapping[PairKey, PairRegistration]


@dataclass(frozen=True)
class MergedGroup:
    """Fragments combined into one by the pre-merge.

    anchor_id: the member with the most points; its local frame is the group's frame.
    member_ids: all members in input order (anchor included).
    transforms: member id -> (4, 4) float64, member-local -> anchor-local.
    points: (M, 3) float64, anchor-local, meters: the members' union, voxel-thinned.
    """

    anchor_id: str
    member_ids: tuple[str, ...]
    transforms: dict[str, FloatArray]
    points: FloatArray


@dataclass(frozen=True)
class PremergeResult:
    """Groups in the input order of their first member; every input id in exactly one."""

    groups: tuple[MergedGroup, ...]


@dataclass(frozen=True)
class _Prepared:
    cloud: o3d.geometry.PointCloud  # downsampled, with normals
    fpfh: o3d.pipelines.registration.Feature
    n: int


def _prepare(points: FloatArray, p: RegistrationParams) -> _Prepared:
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    thinned = voxel_thin(np.asarray(points, np.float64), p.voxel_size)
    down = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(thinned))
    if (n := len(down.points)) < _MIN_POINTS:
        return _Prepared(down, _reg.Feature(), n)
    hybrid = o3d.geometry.KDTreeSearchParamHybrid
    down.estimate_normals(hybrid(p.normal_radius_factor * p.voxel_size, 30))
    search = hybrid(p.feature_radius_factor * p.voxel_size, 100)
    return _Prepared(down, _reg.compute_fpfh_feature(down, search), n)  # type: ignore[call-arg]


def _register_prepared(src: _Prepared, tgt: _Prepared, p: RegistrationParams) -> PairRegistration:
    if min(src.n, tgt.n) < _MIN_POINTS:
        return PairRegistration(np.eye(4), 0.0, float("inf"))
    o3d.utility.random.seed(p.seed)
    ransac_dist = p.ransac_distance_factor * p.voxel_size
    edge_check = _reg.CorrespondenceCheckerBasedOnEdgeLength(p.edge_length_ratio)
    checkers = [edge_check, _reg.CorrespondenceCheckerBasedOnDistance(ransac_dist)]
    est = _reg.TransformationEstimationPointToPoint(False)
    crit = _reg.RANSACConvergenceCriteria(p.ransac_max_iterations, p.ransac_confidence)
    args = (src.fpfh, tgt.fpfh, p.mutual_filter, ransac_dist, est, 3, checkers, crit)
    coarse = _reg.registration_ransac_based_on_feature_matching(src.cloud, tgt.cloud, *args)
    icp_dist = p.icp_distance_factor * p.voxel_size
    crit_icp = _reg.ICPConvergenceCriteria(max_iteration=p.icp_max_iterations)
    args_icp = (coarse.transformation, _reg.TransformationEstimationPointToPlane(), crit_icp)
    fine = _reg.registration_icp(src.cloud, tgt.cloud, icp_dist, *args_icp)
    T = np.asarray(fine.transformation, dtype=np.float64).copy()
    # inliers are counted over the smaller cloud (evaluate_registration's fitness is per source)
    small, big, T_sb = (src, tgt, T) if src.n <= tgt.n else (tgt, src, np.linalg.inv(T))
    ev = _reg.evaluate_registration(small.cloud, big.cloud, icp_dist, T_sb)
    rmse = float(ev.inlier_rmse) if ev.fitness > 0 else float("inf")
    return PairRegistration(T, float(ev.fitness), rmse)


def register_pair(
    source: FloatArray,
    target: FloatArray,
    params: RegistrationParams = RegistrationParams(),
) -> PairRegistration:
    """Register ``source`` onto ``target`` with FPFH + RANSAC, refined by point-to-plane ICP.

    Parameters
    ----------
    source, target : (N, 3), (M, 3) float64, each in its own fragment-local frame, meters.
    params : voxel size, RANSAC and ICP settings; same inputs and seed give the same result.

    Returns
    -------
    PairRegistration
        ``transform`` maps source-local -> target-local. Fewer than 10 points after voxel
        downsampling give identity with ``inlier_ratio`` 0.
    """
    return _register_prepared(_prepare(source, params), _prepare(target, params), params)


def register_all(
    clouds: Mapping[str, FloatArray],
    params: RegistrationParams = RegistrationParams(),
) -> dict[PairKey, PairRegistration]:
    """Register every unordered pair once; features are computed once per cloud.

    Returns ``(a, b) -> PairRegistration`` for ``clouds`` (id -> (N, 3) float64,
    fragment-local), ``a`` before ``b`` in input order; the transform maps a-local -> b-local.
    """
    prep = {k: _prepare(v, params) for k, v in clouds.items()}
    pairs = combinations(clouds, 2)
    return {(a, b): _register_prepared(prep[a], prep[b], params) for a, b in pairs}


def _find(parent: dict[str, str], x: str) -> str:
    while parent[x] != x:
        x = parent[x]
    return x


def _forest(
    ids: Sequence[str], pairs: _Pairs, above: float
) -> tuple[list[PairKey], list[list[str]]]:
    """Max spanning forest of pairs with inlier ratio > ``above``, and its components."""
    edges = [e for e, r in pairs.items() if r.inlier_ratio > above]
    parent = {i: i for i in ids}
    tree = []
    for a, b in sorted(edges, key=lambda e: -pairs[e].inlier_ratio):
        ra, rb = _find(parent, a), _find(parent, b)
        if ra != rb:
            parent[rb] = ra
            tree.append((a, b))
    groups: dict[str, list[str]] = {}
    for i in ids:
        groups.setdefault(_find(parent, i), []).append(i)
    return tree, list(groups.values())


def _chain(root: str, tree: Sequence[PairKey], pairs: _Pairs) -> _Poses:
    """Poses (member-local -> root-local) of the forest component that contains ``root``."""
    poses: _Poses = {root: np.eye(4)}
    frontier = [root]
    while frontier:
        u = frontier.pop()
        for a, b in tree:
            if u not in (a, b) or (a if u == b else b) in poses:
                continue
            T_ab = pairs[(a, b)].transform  # a-local -> b-local
            v, T_vu = (a, T_ab) if u == b else (b, np.linalg.inv(T_ab))
            poses[v] = poses[u] @ T_vu
            frontier.append(v)
    return poses


def _median_spacing(clouds: Sequence[FloatArray]) -> float:
    rng = np.random.default_rng(0)
    picks = [c[rng.choice(len(c), min(5000, len(c)), replace=False)] for c in clouds]
    gaps = [cKDTree(c).query(q, k=2)[0][:, 1] for c, q in zip(clouds, picks, strict=True)]
    return float(np.median(np.concatenate(gaps)))


def _merge(
    members: list[str], clouds: _Clouds, anchor: str, transforms: _Poses, p: RegistrationParams
) -> MergedGroup:
    transforms = {m: transforms[m] for m in members}  # input order
    if len(members) == 1:
        return MergedGroup(anchor, (anchor,), transforms, np.asarray(clouds[anchor]))
    union = np.concatenate([clouds[m] @ T[:3, :3].T + T[:3, 3] for m, T in transforms.items()])
    voxel = p.merge_voxel_size or max(_median_spacing([clouds[m] for m in members]), 1e-3)
    return MergedGroup(anchor, tuple(members), transforms, voxel_thin(union, voxel))


def premerge(
    clouds: Mapping[str, FloatArray],
    params: RegistrationParams = RegistrationParams(),
    *,
    pairs: _Pairs | None = None,
) -> PremergeResult:
    """Combine fragments that overlap with more than ``merge_inlier_ratio`` inliers (paper 3).

    Groups are the connected components of the above-threshold pairs; members are chained to
    the anchor (largest member) along their maximum spanning tree (weights: inlier ratio).

    Parameters
    ----------
    clouds : id -> (N, 3) float64, fragment-local, meters (at most a few dozen fragments).
    params : registration settings and the merge threshold.
    pairs : precomputed :func:`register_all` output for ``clouds``; computed when None.

    Returns
    -------
    PremergeResult
        Singletons are groups of one with identity transform and their own (unthinned) points.
    """
    pairs = register_all(clouds, params) if pairs is None else pairs
    tree, components = _forest(list(clouds), pairs, params.merge_inlier_ratio)
    groups = []
    for members in components:
        anchor = max(members, key=lambda m: len(clouds[m]))  # first of the largest on ties
        groups.append(_merge(members, clouds, anchor, _chain(anchor, tree, pairs), params))
    return PremergeResult(tuple(groups))


def chain_baseline(
    clouds: Mapping[str, FloatArray],
    params: RegistrationParams = RegistrationParams(),
    *,
    pairs: _Pairs | None = None,
) -> dict[str, FloatArray]:
    """FPFH registration baseline (paper Table 1): all pairs, maximum spanning tree, chaining.

    Pairs with ``inlier_ratio <= params.min_edge_inlier_ratio`` (default: failed ones) are
    dropped; the maximum spanning forest of the rest (weights: inlier ratio) is chained from
    the first input id (identity pose). Every other component is chained from its own first
    id, which is placed with identity: the baseline has nothing to place it by.

    Parameters
    ----------
    clouds : id -> (N, 3) float64, fragment-local, meters.
    pairs : precomputed :func:`register_all` output for ``clouds``; computed when None.

    Returns
    -------
    dict
        id -> (4, 4) float64 pose, fragment-local -> baseline site frame, in input order.
    """
    pairs = register_all(clouds, params) if pairs is None else pairs
    tree, components = _forest(list(clouds), pairs, params.min_edge_inlier_ratio)
    poses = {k: T for m in components for k, T in _chain(m[0], tree, pairs).items()}
    return {i: poses[i] for i in clouds}
