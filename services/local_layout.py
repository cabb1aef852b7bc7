"""Local layout of one fragment: the chain of walls it sees (paper 3.1), entry function."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from schemas.params import LayoutParams, PipelineParams
from services.geometry import distance_to_chain, unique_cells
from services.manhattan import estimate_manhattan_frame, thin_with_normals
from services.types import Evidence, FloatArray, LocalLayout, ProgressFn
from services.wall_graph import find_wall_chain
from services.wall_lines import WallLine, find_wall_lines, scan_top

__all__ = [
    "FOOTPRINT_CELL",
    "boundary_points",
    "end_boundaries",
    "estimate_local_layout",
    "footprint_cells",
    "unchained_walls",
    "wall_points_under_ceiling",
]

_MAX_BOUNDARY_POINTS = 4000
FOOTPRINT_CELL = 0.25  # m
_FOOTPRINT_MIN_POINTS = 4
# m: wall cells this close to a chain wall are that wall, placed a little off by the chain
# (a wall line 0.23 m from its wall is a small error, not a missed wall)
_ON_CHAIN = 0.3
# m: an unchained wall must show wall points this close under the ceiling: tall furniture
# (a 2.2 m wardrobe's front passes the wall tests in a 2.5 m room) stops further down
_UNDER_CEILING = 0.12
_UNDER_CEILING_POINTS = 3  # of them within a cell's reach: a stray point is no wall
_VERTICAL = 0.5  # |normal z| under this: a point of a vertical surface
_CELL_SPACINGS = 1.5  # a grid cell spans at least this many point spacings (sparse scans)


def boundary_points(
    aligned: FloatArray, end: FloatArray, inward: FloatArray, band: float, depth: float
) -> FloatArray:
    """Points of the end region at one chain end.

    The region runs from ``band`` beyond the cutting plane through the end (the vertical
    plane perpendicular to the end wall) to ``depth`` inside the chain, across the whole
    scan: wall, floor, ceiling and whatever stands there. Neighbouring scans share what
    crosses their cut (furniture, door jambs), what one saw past its end and, where they
    overlap, the whole overlap. At most 4000 points are kept, evenly strided.

    Parameters
    ----------
    aligned : (M, 3) float64, fragment points, aligned frame.
    end : (2,) the source or target keypoint.
    inward : (2,) unit vector along the end wall, pointing from the end into the chain.
    band : reach beyond the end, meters (the paper's boundary band).
    depth : reach into the chain, meters.
    """
    distance = (aligned[:, :2] - end) @ inward
    near = aligned[(distance > -band) & (distance < depth)]
    stride = max(1, int(np.ceil(len(near) / _MAX_BOUNDARY_POINTS)))
    return near[::stride].copy()


def footprint_cells(aligned: FloatArray, cell: float = FOOTPRINT_CELL) -> FloatArray:
    """Centres of the coarse cells holding at least a few points (outliers drop out).

    Parameters
    ----------
    aligned : (M, 3) float64, thinned points in the aligned frame.
    cell : cell size, meters.

    Returns
    -------
    (F, 2) float64 cell centres, aligned frame.
    """
    if len(aligned) == 0:
        return np.zeros((0, 2))
    ij = np.floor(aligned[:, :2] / cell).astype(np.int64)
    cells, counts = unique_cells(ij)
    centres: FloatArray = ((cells[counts >= _FOOTPRINT_MIN_POINTS] + 0.5) * cell).astype(np.float64)
    return centres


def unchained_walls(
    lines: Sequence[WallLine],
    keypoints: FloatArray,
    under_ceiling: FloatArray,
    params: LayoutParams,
) -> FloatArray:
    """(W, 2) centres of the wall cells with high evidence, in runs as long as the shortest
    candidate wall, that lie off every wall of the chain and rise to the ceiling (points of
    ``under_ceiling`` within a cell: (P, 2) positions of wall points just under it): walls
    the scan shows and the chain does not follow, aligned frame."""
    cells = [line.high_cells(params.min_wall_cells) for line in lines]
    centres = np.concatenate([np.zeros((0, 2)), *cells])
    if len(keypoints) < 2 or len(centres) == 0 or len(under_ceiling) == 0:
        return np.zeros((0, 2))
    centres = centres[distance_to_chain(centres, keypoints) > _ON_CHAIN]
    if len(centres) == 0:
        return centres
    near = cKDTree(under_ceiling).query_ball_point(centres, params.cell_size, return_length=True)
    kept: FloatArray = centres[near >= _UNDER_CEILING_POINTS]
    return kept


def wall_points_under_ceiling(
    aligned: FloatArray, normals: FloatArray, ceiling_z: float | None
) -> FloatArray:
    """(P, 2) positions of the points of vertical surfaces just under the ceiling (or the
    top of the scan when it saw no ceiling), aligned frame."""
    if len(aligned) == 0:
        return np.zeros((0, 2))
    top = scan_top(aligned, ceiling_z)
    near = (aligned[:, 2] > top - _UNDER_CEILING) & (np.abs(normals[:, 2]) < _VERTICAL)
    positions: FloatArray = aligned[near, :2]
    return positions


def end_boundaries(
    aligned: FloatArray, keypoints: FloatArray, band: float, depth: float
) -> tuple[FloatArray, FloatArray]:
    """The end regions (:func:`boundary_points`) around a chain's (K >= 2, 2) source and
    target."""
    return (
        boundary_points(aligned, keypoints[0], _unit(keypoints[1] - keypoints[0]), band, depth),
        boundary_points(aligned, keypoints[-1], _unit(keypoints[-2] - keypoints[-1]), band, depth),
    )


def _unit(v: FloatArray) -> FloatArray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


def estimate_local_layout(
    points: FloatArray,
    params: PipelineParams = PipelineParams(),
    progress: ProgressFn | None = None,
) -> LocalLayout:
    """Estimate the wall chain a fragment sees.

    Parameters
    ----------
    points : (N, 3) float64, fragment-local frame, meters, finite.
    params : all algorithm parameters (Manhattan and layout sections are used).
    progress : optional callback ``(stage, fraction)``.

    Returns
    -------
    LocalLayout
        Keypoints in the aligned frame (empty when no wall was found), the Manhattan frame
        and the boundary points at both chain ends; evidence ``"thin_cloud"`` for a cloud
        of fewer than ``layout.min_calibrated_points`` points.
    """
    report = progress or (lambda stage, fraction: None)
    report("manhattan", 0.0)
    evidence: Evidence = (
        "thin_cloud" if len(points) < params.layout.min_calibrated_points else "cloud"
    )
    cloud = thin_with_normals(points, params.manhattan)
    frame = estimate_manhattan_frame(cloud, params.manhattan)
    aligned = cloud.points @ frame.rotation.T
    normals = cloud.normals @ frame.rotation.T
    report("walls", 0.4)
    # A thin cloud's walls are read on cells wide enough to hold a few of its points each:
    # on 8 cm cells a wall 10 cm between points breaks into short runs.
    on_grid = params.layout
    if _CELL_SPACINGS * cloud.spacing > on_grid.cell_size:
        on_grid = on_grid.model_copy(update={"cell_size": _CELL_SPACINGS * cloud.spacing})
    lines = find_wall_lines(
        aligned, normals, frame.floor_z, frame.ceiling_z, on_grid, thin=evidence == "thin_cloud"
    )
    report("chain", 0.7)
    chain = find_wall_chain(lines, on_grid)
    if chain is None or len(chain.keypoints) < 2:
        report("done", 1.0)
        return LocalLayout(
            keypoints=np.zeros((0, 2)),
            frame=frame,
            footprint=footprint_cells(aligned),
            evidence=evidence,
        )
    kp = chain.keypoints
    band, depth = params.layout.end_region_beyond, params.layout.end_region_depth
    source_boundary, target_boundary = end_boundaries(aligned, kp, band, depth)
    layout = LocalLayout(
        keypoints=kp,
        frame=frame,
        source_boundary=source_boundary,
        target_boundary=target_boundary,
        footprint=footprint_cells(aligned),
        evidence=evidence,
        unchained_walls=unchained_walls(
            lines, kp, wall_points_under_ceiling(aligned, normals, frame.ceiling_z), on_grid
        ),
    )
    report("done", 1.0)
    return layout
