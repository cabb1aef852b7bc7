"""Synthetic scenes with ground truth: one rectilinear room scanned in partial fragments.

Modules: :mod:`~services.synthetic.scene` (the spec, the scene and its ground truth),
:mod:`~services.synthetic.room` (rectilinear rooms), :mod:`~services.synthetic.furniture`
(doors, windows, furniture) and :mod:`~services.synthetic.scan` (what one scan sees).
"""

from services.synthetic.scene import (
    SceneSpec,
    SyntheticFragment,
    SyntheticScene,
    generate_scene,
    ground_truth_json,
)

__all__ = [
    "SceneSpec",
    "SyntheticFragment",
    "SyntheticScene",
    "generate_scene",
    "ground_truth_json",
]
