"""The specimen in the IR image: its pixel mask, which points it sees, their footprint, extrapolation from the edge.

Modules
-------
* :mod:`.mask`: point normals, facing the camera, the specimen's pixel mask
  (the projected point cloud's triangulation, rasterised and eroded), the
  distance of a pixel position to the mask's edge.
* :mod:`.visibility`: the projection of the DIC points into every IR frame
  (:class:`~.visibility.Projection`), the masks per frame and which points
  face the camera.
* :mod:`.extrapolation`: the points just outside the mask, extrapolated
  along the mask's inward direction.
* :mod:`.temperature`: the footprint temperature, a box of pixels around
  each point fitted in the same tile factorisations as the point itself.
* :mod:`.fields`: the fields stage's side of the footprint temperatures
  (the temperatures regressed, their noise probes, the paper's value).

The package's initialiser imports none of its modules, so that the fields
stage's code hash (:mod:`irdic.codehash`) does not cover the projection code
that only the couple stage runs.
"""
