"""Synthetic scenes with ground truth: one rectilinear room scanned in partial fragments.

Modules: :mod:`~services.synthetic.scene` (the spec, its presets, the scene and its ground
truth), :mod:`~services.synthetic.room` (rectilinear rooms),
:mod:`~services.synthetic.families` (room shape families), :mod:`~services.synthetic.shapes`
(cleaning of real room outlines), :mod:`~services.synthetic.cuts` (where the loop is cut into
the fragments' stretches), :mod:`~services.synthetic.furniture` (doors, windows, furniture)
and :mod:`~services.synthetic.scan` (what one scan sees).
"""

from services.synthetic.scene import (
    Junction,
    SceneSpec,
    SyntheticFragment,
    SyntheticScene,
    generate_scene,
    ground_truth_json,
)

__all__ = [
    "Junction",
    "SceneSpec",
    "SyntheticFragment",
    "SyntheticScene",
    "generate_scene",
    "ground_truth_json",
]
