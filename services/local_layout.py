"""Local layout of one fragment: the chain of walls it sees (paper 3.1), entry function."""

from __future__ import annotations

import numpy as np

from schemas.params import PipelineParams
from services.manhattan import estimate_manhattan_frame, thin_with_normals
from services.types import Evidence, FloatArray, LocalLayout, ProgressFn
from services.wall_graph import find_wall_chain
from services.wall_lines import find_wall_lines

__all__ = ["FOOTPRINT_CELL", "boundary_points", "estimate_local_layout", "footprint_cells"]

_MAX_BOUNDARY_POINTS = 4000
FOOTPRINT_CELL = 0.25  # m
_FOOTPRINT_MIN_POINTS = 4


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
    cells, counts = np.unique(ij, axis=0, return_counts=True)
    centres: FloatArray = ((cells[counts >= _FOOTPRINT_MIN_POINTS] + 0.5) * cell).astype(np.float64)
    return centres


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
    lines = find_wall_lines(aligned, normals, frame.floor_z, frame.ceiling_z, params.layout)
    report("chain", 0.7)
    chain = find_wall_chain(lines, params.layout)
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
    layout = LocalLayout(
        keypoints=kp,
        frame=frame,
        source_boundary=boundary_points(aligned, kp[0], _unit(kp[1] - kp[0]), band, depth),
        target_boundary=boundary_points(aligned, kp[-1], _unit(kp[-2] - kp[-1]), band, depth),
        footprint=footprint_cells(aligned),
        evidence=evidence,
    )
    report("done", 1.0)
    return layout
