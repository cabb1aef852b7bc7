"""Algorithm parameters, with the paper's defaults.

These are plain pydantic models (not settings): they travel inside jobs and can be
overridden per run. Deployment settings live in :mod:`schemas.settings`.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from schemas.frames import FrameParams

__all__ = [
    "LayoutParams",
    "ManhattanParams",
    "ParserLimits",
    "PipelineParams",
    "PlacementParams",
    "RegistrationParams",
]


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class ParserLimits(_Frozen):
    """Bounds on what a fragment file may contain."""

    min_points: int = Field(1000, ge=1, description="fewest finite points a usable fragment has")
    max_points: int = Field(5_000_000, ge=1, description="most points a fragment may declare")


class ManhattanParams(_Frozen):
    """Plane extraction and Manhattan-frame estimation (paper 3.1, preprocessing)."""

    voxel_size: float = Field(0.05, gt=0, description="thinning before plane search, m")
    ransac_distance: float = Field(0.03, gt=0, description="plane inlier distance, m")
    ransac_iterations: int = Field(300, ge=10)
    max_planes: int = Field(12, ge=1)
    min_plane_fraction: float = Field(0.01, gt=0, lt=1, description="smallest plane kept")
    max_tilt_deg: float = Field(30.0, gt=0, lt=90, description="largest accepted tilt of up")


class LayoutParams(_Frozen):
    """Local layout estimation on the projection grid (paper 3.1)."""

    cell_size: float = Field(0.08, gt=0, description="grid cell size s, m")
    min_cell_points: int = Field(
        20,
        ge=1,
        description="N: a cell is high wall-evidence when its column holds at least N points "
        "after thinning to one point per s-sized voxel (N*s of wall height)",
    )
    complexity_penalty: float = Field(0.1, ge=0, description="lambda in the edge weight")
    boundary_band: float = Field(0.10, gt=0, description="half-width of the boundary band, m")
    min_wall_cells: int = Field(3, ge=1, description="shortest candidate wall segment, cells")
    frame: FrameParams = Field(
        default_factory=FrameParams,
        description="RGB-D frames: depth range, pixel stride, merging of overlapping frames",
    )
    source_target: Literal["evidence", "spanning_forest"] = Field(
        "evidence",
        description="how the chain is chosen: the simple path that explains the most wall "
        "evidence less a price per corner, or the paper's min-cost path between the ends of "
        "the longest path in the ST-graph's spanning forest",
    )


class PlacementParams(_Frozen):
    """Global placement energy and search (paper 3.2)."""

    use_complexity: bool = True
    use_closure: bool = True
    use_boundary: bool = True
    use_free_space: bool = Field(
        True, description="penalise scanned space that a placement puts outside the room"
    )
    free_space_weight: float = Field(
        10.0, ge=0, description="energy per fragment lying wholly outside the room"
    )
    free_space_margin: float = Field(
        0.3, ge=0, description="footprint cells this close outside a wall still count inside, m"
    )
    boundary_sigma: float = Field(0.10, gt=0, description="sigma of the mismatch CDF, m")
    min_boundary_points: int = Field(50, ge=1)
    max_closure_share: float = Field(
        0.05,
        gt=0,
        description="largest closure gap before refinement, as a share of the loop's wall "
        "length (at least 1 m), for the loop to count as closed; a larger gap means walls are "
        "missing, and the refinement would only hide it",
    )
    closure_overshoot: float = Field(
        1.5,
        gt=0,
        description="how far the loop's last wall may run past its start before the loop "
        "is refined (neighbouring scans overlap; the overlaps add up around the loop), m",
    )
    closure_tolerance: float = Field(
        0.05, gt=0, description="largest gap left in the loop after refinement, m"
    )
    top_k: int = Field(3, ge=1, description="best placements kept (runners-up in diagnostics)")
    max_search_seconds: float = Field(
        4.0, gt=0, description="search time before the best found so far is returned, s"
    )
    max_search_nodes: int = Field(
        100_000, ge=1, description="search nodes before the best found so far is returned"
    )


class RegistrationParams(_Frozen):
    """FPFH + RANSAC + ICP registration and pre-merge parameters (paper 3, Table 1)."""

    voxel_size: float = Field(0.05, gt=0, description="downsampling voxel before features, m")
    normal_radius_factor: float = Field(2.0, gt=0, description="normal radius / voxel")
    feature_radius_factor: float = Field(5.0, gt=0, description="FPFH radius / voxel")
    ransac_distance_factor: float = Field(1.5, gt=0, description="RANSAC inlier dist / voxel")
    edge_length_ratio: float = Field(0.9, gt=0, lt=1, description="edge-length checker")
    ransac_max_iterations: int = Field(100_000, ge=1)
    ransac_confidence: float = Field(0.999, gt=0, lt=1)
    mutual_filter: bool = True
    icp_distance_factor: float = Field(1.5, gt=0, description="ICP / inlier distance / voxel")
    icp_max_iterations: int = Field(50, ge=1)
    merge_inlier_ratio: float = Field(0.6, ge=0, le=1, description="pre-merge threshold (paper)")
    # thinning voxel of merged clouds, m; None: members' median point spacing (>= 1 mm)
    merge_voxel_size: float | None = Field(None, gt=0)
    # chain_baseline drops pairs at or below this inlier ratio (0: only failed registrations)
    min_edge_inlier_ratio: float = Field(0.0, ge=0, le=1)
    seed: int = Field(0, ge=0, description="Open3D random seed, set before every RANSAC run")


class PipelineParams(_Frozen):
    """Every algorithm parameter, grouped by stage."""

    parser: ParserLimits = ParserLimits()
    manhattan: ManhattanParams = ManhattanParams()
    layout: LayoutParams = LayoutParams()
    placement: PlacementParams = PlacementParams()
    registration: RegistrationParams = RegistrationParams()
