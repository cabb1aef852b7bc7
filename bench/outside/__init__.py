"""Outside scenes: a held-out benchmark made by generators written without looking at
``services/synthetic``.

Two generators were written apart from the project, on purpose, to see how ``jigsaw align``
does on scenes it was never tuned on:

- :mod:`bench.outside.clouds`: point-cloud rooms under another cut model: the wall loop cut
  into arcs whose floor, ceiling and furniture are Voronoi-like sectors (the points nearest
  each arc's walls), fans of the next room's floor and far walls seen through doors, and a
  density and noise of its own for each fragment;
- :mod:`bench.outside.frames`: RGB-D frame rooms from another renderer (open3d ray
  casting), seen from 1-3 stations at least 1.2 m apart.

:mod:`bench.outside.score` scores a result against a scene's truth (the paper's ACC_global
through the best anchor fragment, a strict variant, top-3, pose errors) and
:mod:`bench.outside.run` runs the whole: ``python -m bench.outside.run clouds|frames ...``.
Real outlines come from the test split of the MatterportLayout shapes
(:mod:`bench.room_shapes`).

Use these scenes ONLY to measure how far the project's figures hold on scenes it was not
tuned on: never to fit or choose parameters, thresholds or methods on them (that would make
them one more tune set and end what they are for).
"""
