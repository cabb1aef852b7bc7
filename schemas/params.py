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
    end_region_depth: float = Field(
        1.0,
        gt=0,
        description="how far into the chain the end regions kept for junction evidence reach, m",
    )
    end_region_beyond: float = Field(
        1.0, gt=0, description="and how far past the chain's end (what the scan saw there), m"
    )
    min_wall_cells: int = Field(3, ge=1, description="shortest candidate wall segment, cells")
    min_calibrated_points: int = Field(
        15_000,
        ge=0,
        description="a cloud of fewer points is thinner than any the confidence was fitted on "
        "(19 000 and more; at 8 000-15 000 a chain is wrong about twice as often): its room "
        "is calibrated apart (placement.thin_cloud_calibration)",
    )
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
    """Global placement energy, search and confidence (paper 3.2, extended).

    The energy is a weighted sum of features (``services.placement.energy``); the weights
    are fitted on the project's benchmark so that the Boltzmann distribution over the
    assemblies found gives calibrated probabilities (``bench/tune_placement.py``).
    """

    use_complexity: bool = Field(True, description="the paper's E_l: junction corners, hull")
    use_closure: bool = Field(True, description="the paper's E_c, as a likelihood")
    use_boundary: bool = Field(True, description="the paper's E_b boundary mismatch")
    use_structure: bool = Field(True, description="structure seen on both sides of a cut")
    use_free_space: bool = Field(
        True, description="penalise walls through space another scan saw empty"
    )
    use_outside: bool = Field(
        True, description="penalise floor a scan saw that the closed room leaves outside"
    )
    weight_turn: float = Field(0.38, ge=0, description="energy per junction that turns")
    weight_hull: float = Field(0.569, ge=0, description="energy per convex-hull edge")
    weight_closure: float = Field(0.414, ge=0, description="weight of the closure likelihood")
    weight_structure: float = Field(2.897, ge=0, description="weight of the structure evidence")
    weight_boundary: float = Field(2.395, ge=0, description="weight of the boundary mismatch")
    weight_conflict: float = Field(
        0.624, ge=0, description="energy per meter of wall through another scan's seen space"
    )
    conflict_drift_sigmas: float = Field(
        1.0,
        ge=0,
        description="with prior poses, a wall counts as through another scan's seen space "
        "only this many standard deviations of the junctions' hidden displacement between "
        "the two pieces deep inside it, each moved by that displacement's mean (0: at any "
        "depth). Without priors every wall counts where the end-to-end loop puts it: there "
        "the far pieces' conflict is what tells many wrong rooms, and forgiving it lost "
        "rooms on both splits (bench.placement_trust)",
    )
    weight_outside: float = Field(
        3.844, ge=0, description="energy per m² of seen floor the closed room leaves outside"
    )
    frame_weights: tuple[float, ...] | None = Field(
        (2.774, 1.014, 0.61, 4.093, 4.824, 2.648, 0.127),
        min_length=7,
        max_length=7,
        description="the seven weights above (turn, hull, closure, structure, boundary, "
        "conflict, outside) for pieces that are RGB-D frames, blended by the share of frame "
        "pieces: a frame's few walls and sparse ends weigh the evidence differently from a "
        "cloud's (python -m bench.tune_placement --frames); None weighs frames as clouds",
    )
    outside_cap: float = Field(
        1.0,
        gt=0,
        description="the most seen floor outside the room that counts per piece (floor seen "
        "through a doorway, past a chain a little wrong, is outside the true room too), m²",
    )
    outside_margin: float = Field(
        0.3,
        ge=0,
        description="seen floor counts as outside the room only this far beyond its boundary "
        "(the unrefined loop's junctions may be off by an overlap or gap), m",
    )
    junction_mean: float = Field(
        0.0, description="mean hidden displacement along the wall at a junction (overlap < 0), m"
    )
    junction_sigma: float = Field(
        0.3, gt=0, description="its spread (root mean square about the mean), m"
    )
    # Measured between the true chain ends at straight junctions: mean -0.21 m on the tune
    # split (1 500 junctions), -0.19 m on outside clouds (seed 18, 840); spread 0.25 m. Only
    # the refinement takes it: in the energy's closure term the same mean made rooms whose
    # loop leaves a large gap (a door or clutter at a cut) lose most of their confidence.
    refined_junction_mean: float = Field(
        -0.2,
        description="mean displacement along the wall at a straight junction the refinement "
        "assumes (overlap < 0), m",
    )
    hidden_corner_mean: float = Field(
        0.0, ge=0, description="mean unseen wall on each side of a corner hidden in a cut, m"
    )
    hidden_corner_sigma: float = Field(0.3, gt=0, description="its spread, m")
    keypoint_sigma: float = Field(0.05, gt=0, description="noise of a chain end's position, m")
    open_end_angle: float = Field(
        10.0,
        ge=0,
        description="a single frame's chain end is open when its view continues past it by "
        "at least this azimuth (degrees; services.open_ends): the junction there may hide "
        "metres of wall or a step of the room. 0: no end is open",
    )
    open_end_least_view: float = Field(
        1.2,
        ge=0,
        description="RGB-D frames: the narrowest view (radians across) whose chain ends may "
        "be open: a kinect's (1.09) won no room by them and lost two (held-out 1000, "
        "outside seed 17's kinect_014: a chain seen through a door, open at both ends)",
    )
    open_end_sigma: float = Field(
        1.5,
        gt=0,
        description="spread an open end adds to its junction's hidden displacement, per "
        "axis, in the energy's closure and the refinement; the closed-loop gap limit allows "
        "that much more per open end, m",
    )
    measured_shift_sigma: float = Field(
        0.06,
        gt=0,
        description="spread of an overlap or gap along the wall that the two ends' structure "
        "measures (10 cm voxels; median error 3 cm on the benchmark's true junctions), m",
    )
    station_reach: float = Field(
        0.6,
        ge=0,
        description="RGB-D frames: cameras of two pieces the refined loop puts closer than "
        "this are taken as one station (a robot turning on the spot, a tripod) and made to "
        "coincide (stations of one room lie farther apart: at 0.8-1 m the benchmark's "
        "generator's stations of one room were taken as one and rooms lost); also the most a "
        "camera adds to the stations term (a camera farther from every other piece's stands "
        "at a station of its own); 0 turns both off, m",
    )
    station_sigma: float = Field(
        0.05, gt=0, description="how closely the cameras of one station coincide, m"
    )
    station_weight: float = Field(
        1.0,
        ge=0,
        description="RGB-D frames: energy per unit of the kept assemblies' stations term "
        "(services.stations: each camera's distance to the nearest other piece's, at most "
        "station_reach, squared over twice station_spread squared); 0 turns it off",
    )
    station_spread: float = Field(
        0.3,
        gt=0,
        description="RGB-D frames: the scale of the stations term: a camera this far from "
        "the nearest other piece's costs 0.5, m",
    )
    station_occam: float = Field(
        2.0,
        ge=0,
        description="RGB-D frames: what the stations term adds per station beyond the "
        "first that the refined cameras stand at (cameras within station_reach are one): "
        "each station is one more position to place anywhere in the room, about "
        "log(room area / the area a station's cameras spread over) = 2-4 nats more than "
        "one its cameras share (outside frames seeds 22-25: 2 and 4 did alike), so of two "
        "assemblies whose cameras each have a partner nearby, the one whose cameras stand "
        "at fewer stations is likelier; 0 turns it off",
    )
    station_mate_cost: float = Field(
        1.5,
        ge=0,
        description="RGB-D frames: what the stations term adds per pair of frames whose "
        "views say they share their camera at one quarter turn (Piece.station_mates) that "
        "an assembly turns otherwise: of the pairs passing that test on outside frame rooms "
        "85 % shared the truth's camera and turn, so an assembly breaking one is about "
        "log(0.85 / 0.15) = 1.7 nats less likely (outside frames seeds 22-27 and 28: 1.5 "
        "and 3 gained alike, 3 also lost a room); 0 turns it off",
    )
    end_wall_trial: float = Field(
        1.3,
        ge=0,
        description="RGB-D frames: a chain's first or last wall no longer than this that "
        "turns off a longer wall at a convex corner may be a furniture side or front at the "
        "view's edge; the site is also placed with the chain without it, one such wall at a "
        "time, and keeps it so when the room then closes with an energy lower by "
        "end_wall_prior (services.end_walls); 0 turns it off, m",
    )
    end_wall_least_view: float = Field(
        1.2,
        ge=0,
        description="RGB-D frames: the narrowest view (radians across) whose chains the "
        "end-wall trial is given: a kinect's (1.09) lost more rooms by it than it won "
        "(tune, held-out and outside draws: 3 won, 5 lost; realsense and wide 11 won, 2 "
        "lost)",
    )
    end_wall_prior: float = Field(
        1.0,
        ge=0,
        description="RGB-D frames: the energy a chain without such an end wall must gain to "
        "be kept: a prior against the trim, since most short convex end walls are the "
        "room's own corners (about one in four a furniture side)",
    )
    runner_up_prior: float = Field(
        3.0,
        ge=0,
        description="RGB-D frames: the energy the wall graph's runner-up chain of a frame "
        "must gain over its chosen one to replace it (the site is placed once more with "
        "each frame's runner-up, where it has one); inf turns the trial off, nats",
    )
    end_step_depth: float = Field(
        0.8,
        ge=0,
        description="RGB-D frames: a chain that ends by turning off a wall onto a front and "
        "back onto a side no longer than this (furniture standing in the corner at the "
        "view's edge) is also tried with the front moved back onto the wall the side meets, "
        "given to the same views and kept as the end-wall trial keeps its variants "
        "(end_wall_least_view, end_wall_prior; services.end_walls; a kinect's held-out "
        "1000-1039 lost a room by it, outside seed 24 won one); 0 turns it off, m",
    )
    station_view_overlap: float = Field(
        8.0,
        ge=0,
        description="RGB-D frames: the least arc, degrees, over which two frames' views must "
        "overlap for their wall ranges to say they share a camera (services.view_ranges); a "
        "shared camera is then joined in every assembly that turns the two frames as the "
        "ranges do; 0 turns it off",
    )
    station_view_share: float = Field(
        0.9,
        gt=0,
        le=1,
        description="RGB-D frames: the share of that arc where the two frames' wall ranges "
        "must agree",
    )
    station_view_tolerance: float = Field(
        0.05,
        gt=0,
        description="RGB-D frames: how far two frames' wall ranges may differ in one "
        "direction and still agree, m (plus 1 % of the range)",
    )
    station_outlier: float = Field(
        0.25,
        gt=0,
        description="cameras taken as one station that the refined loop still leaves farther "
        "apart are another station's after all (the walls between them say so), m",
    )
    boundary_band: float = Field(0.10, gt=0, description="paper's boundary band, m")
    boundary_sigma: float = Field(0.10, gt=0, description="sigma of the mismatch CDF, m")
    min_boundary_points: int = Field(50, ge=1)
    hint_pair_cost: float = Field(
        6.0, ge=0, description="energy per known neighbour pair or order step an assembly breaks"
    )
    max_closure_share: float = Field(
        0.05,
        gt=0,
        description="largest closure gap before refinement, as a share of the loop's wall "
        "length (at least 1 m), for the loop to count as closed; a larger gap means walls are "
        "missing, and the refinement would only hide it",
    )
    straight_junction_slack: float = Field(
        0.5,
        ge=0,
        description="what each straight junction may add to that gap: an overlap or gap "
        "between neighbouring scans, unseen wall at a door, m",
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
    share_corners: bool = Field(
        True,
        description="RGB-D frames: a junction may join two pieces that both saw the same "
        "corner (the next piece starts before the corner the last one turned): the corners "
        "coincide and the walls either side overlap, instead of a hidden corner the other "
        "way (services.placement.corners)",
    )
    top_k: int = Field(24, ge=1, description="assemblies kept by the search")
    energy_window: float = Field(
        6.0,
        gt=0,
        description="assemblies whose energy exceeds the best's by more are not kept (they "
        "are e^6 = 400 times less likely): the search prunes at that bound",
    )
    beam_width: int = Field(
        1000,
        ge=0,
        description="partial loops a first, breadth-first pass keeps per loop position (0: "
        "none; at most half the node budget in all): a true partial loop can rank a few "
        "hundredth in the middle of the loop before its later junctions pay off",
    )
    large_site_pieces: int = Field(
        9,
        ge=1,
        description="sites of this many pieces or more are searched as large ones: the whole "
        "beam width, and no exact finish in the children's bounds (there the node budget "
        "decides, and the finish costs time without finding better loops). Each piece fewer "
        "divides the beam by 3: a small site's depth-first search finishes anyway",
    )
    max_search_nodes: int = Field(
        20_000,
        ge=1,
        description="search nodes before the best found so far is returned (a count, not a "
        "time: the same input gives the same answer on any machine)",
    )
    max_open_nodes: int = Field(
        2_000, ge=1, description="search nodes of the fallback search for an open chain"
    )
    polish_nodes: int = Field(
        5_000,
        ge=0,
        description="search nodes (pieces placed) spent, when the search ran out of its "
        "budget, on loops one move away from the best found: a piece moved elsewhere in the "
        "loop at any quarter turn, with the piece it then precedes at any quarter turn (0: "
        "none)",
    )
    restart_roots: int = Field(
        1,
        ge=0,
        description="when the search ran out of its budget without prior poses: other "
        "searches entering the loop at as many other pieces (spread evenly), whose loops "
        "compete with the first's (0: none)",
    )
    restart_nodes: int = Field(
        5_000, ge=1, description="search nodes of each of those other searches"
    )
    frame_refit_deg: float = Field(
        5.0,
        ge=0,
        description="with prior poses: when the hints frame's yaw fitted to the best loop "
        "differs from the priors' own estimate (known only modulo a quarter turn) by more "
        "than this (degrees), the pieces are searched again in the fitted frame and the "
        "lower energy kept (tune split, priors of 1.5 m / 20 deg: 2 and 5 degrees made the "
        "same rooms right, 5 in 9 % less time at 13-16 fragments)",
    )
    unexplored_energy: float = Field(
        4.818,
        description="energy above the best of the 'none of these' alternative (local layouts "
        "wrong, truth not found) in the confidence",
    )
    unexplored_per_piece: float = Field(
        -0.32, description="change of that energy per piece (more pieces, more to go wrong)"
    )
    placed_prior_sigma: float = Field(
        1.5,
        gt=0,
        description="the confidence counts a piece with a prior pose as placed by the fleet, "
        "not by the search, in proportion to how much narrower than this (meters, its "
        "position's standard deviation) the prior is: a prior this wide or wider leaves its "
        "piece as free as one without (priors of 1.5 m / 20 deg on the tune split: counted "
        "as placed, 9-16 fragment rooms right 36 % at confidence 0.16, 83 % at 0.38; Brier "
        "0.097 -> 0.080)",
    )
    confidence_coefficients: tuple[float, ...] = Field(
        (1.233, 1.385, 0.139, -0.433, -0.336, -0.186, -0.649),
        min_length=7,
        max_length=7,
        description="logistic calibration of the main room's probability over "
        "(bias, logit of its Boltzmann share, pieces, its closure term, its free-space "
        "conflict, its hidden corners, search truncated); (0, 1, 0, ...) is the share itself",
    )
    frame_calibration: tuple[float, float] = Field(
        (-0.159, 0.398),
        description="(bias, slope) mapping the main room's calibrated logit z to a + b z when "
        "its pieces are RGB-D frames (a share of the pieces: that share of the change): a "
        "frame's chain is wrong more often than a cloud's (bench/rgbd_frames.py --fit, tune "
        "seeds; then refitted with the slopes below on outside frame draws, seeds 22-25, "
        "checked on 26-27: bench/outside/fit_frames.py); (0, 1) leaves frames as clouds",
    )
    frame_view_slope: float = Field(
        -0.064,
        description="change of that logit per radian the frames see across beyond the "
        "kinect's 63 degrees (a wider camera's chains are right more often, but its rooms "
        "reach higher logits still; bench/rgbd_frames.py --fit over several cameras)",
    )
    frame_view_top_slope: float = Field(
        -11.456,
        le=0,
        description="change of that logit per radian the top of the frames' views lies "
        "below 4 degrees above level, the lowest the calibration was fitted on (a camera "
        "looking steeply down sees only its walls' feet; bench/rgbd_frames.py "
        "--fit-view-top)",
    )
    frame_station_slope: float = Field(
        -1.347,
        le=0,
        description="change of that logit per station beyond two that the main room's "
        "refined cameras stand at (cameras of several pieces within station_reach are one "
        "station): the map was fitted on rooms seen from 1-3 stations, and rooms whose "
        "frames scatter over more were wrong more often than it says (tune seeds, also "
        "overlapping by up to 2 m and leaving up to 1 m unseen: 128 of 395 rooms, right "
        "31 %, mean confidence 0.59 -> 0.30; bench/rgbd_frames.py --fit-stations)",
    )
    thin_cloud_calibration: tuple[float, float] = Field(
        (-0.01, 0.672),
        description="the same map for clouds thinner than layout.min_calibrated_points "
        "(bench/sensor_stress.py --fit, tune seeds)",
    )
    loose_room_slack: float = Field(
        0.7,
        gt=0,
        description="a main room whose pieces the junctions leave free to slide by this much "
        "or more (one standard deviation, in units of 5 % of its diagonal: "
        "services.confidence.room_slack) is a loose room: its size is a guess",
    )
    loose_room_confidence: float = Field(
        0.75,
        ge=0,
        le=1,
        description="the most a loose room's confidence can be: of the tune split's rooms "
        "calibrated at 0.95 or more, 6 of the 8 loose ones were right (81 of 82 others)",
    )
    unexplained_wall_limit: float = Field(
        0.24,
        gt=0,
        description="meters of wall the scans show inside the main room, off its floorplan "
        "(services.wall_evidence), from which the floorplan misses a wall: a fin or notch "
        "a chain cut across (the shortest candidate wall: 3 cells of 0.08 m)",
    )
    unexplained_wall_confidence: float = Field(
        0.25,
        ge=0,
        le=1,
        description="the most such a room's confidence can be: of the tune split's rooms "
        "with that much wall unexplained, 2 of 9 were right by the paper's test (5 of 12 on "
        "the test split: the missed wall is often a short fin the test forgives)",
    )
    conflict_wall_limit: float = Field(
        2.0,
        gt=0,
        description="meters of the main room's walls running through space another scan "
        "saw empty (the energy's conflict term, unrefined loop) from which it is not said "
        "closed: a wall the chains missed, closed over by walls where the scans saw floor",
    )
    conflict_confidence: float = Field(
        0.98,
        ge=0,
        le=1,
        description="the most such a room's confidence can be (below closed_confidence)",
    )
    implausible_hints_odds: float = Field(
        0.001,
        gt=0,
        le=1,
        description="with prior poses: a prior the main room misses by so much that honest "
        "priors (as wide as their standard deviations say) would miss by as much less often "
        "than this, over all the site's priors, is implausible; a room with two or more such "
        "is not said closed (one is a fleet's mistake as likely as the room's). A room of the "
        "test split was closed at 0.990 with two priors 5 and 6 standard deviations off, its "
        "notch 2.3 m from where it is",
    )
    contradicted_hints_confidence: float = Field(
        0.98,
        ge=0,
        le=1,
        description="the most such a room's confidence can be (below closed_confidence)",
    )
    truncated_search_confidence: float = Field(
        0.98,
        ge=0,
        le=1,
        description="the most a room's confidence can be when the search ran out of nodes "
        "and no prior poses led it: the assemblies it kept may all be one room's near-copies "
        "while a rival lay beyond the budget, so it cannot say no serious rival exists (a "
        "15-fragment corridor of the outside benchmark was closed at 0.995 and wrong, its 24 "
        "kept assemblies 22 copies of one room)",
    )
    relaxed_refinement_confidence: float = Field(
        0.25,
        ge=0,
        le=1,
        description="the most a room's confidence can be when its refinement had to drop "
        "the junction inequalities (the measured walls do not fit the loop): of 700 "
        "benchmark rooms (tune and test), 3 of 12 such main rooms were right, and 1 of "
        "them had been said closed",
    )
    closed_confidence: float = Field(
        0.99,
        gt=0,
        le=1,
        description="confidence at or above which a closed loop is reported 'closed'; below "
        "it, 'ambiguous' with the alternatives",
    )
    max_alternatives: int = Field(3, ge=1, description="alternatives reported at most")
    min_alternative_probability: float = Field(
        0.005, ge=0, le=1, description="alternatives less probable than this are not reported"
    )
    same_room_share: float = Field(
        0.025,
        gt=0,
        description="two assemblies whose floorplans differ by less than this share of the "
        "room diagonal (mean keypoint distance) are one answer",
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
