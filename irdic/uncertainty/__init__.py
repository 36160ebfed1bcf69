"""The per-point standard uncertainty of the fields stage's results.

Modules
-------
* :mod:`.model`: :func:`~.model.uncertainties`, every field's std and its
  ``*_bias_dominated`` flags, from the IR and DIC noise propagated through
  the fields' own operators plus the regressions' estimated bias.
* :mod:`.probes`: the random noise probes and the times they are run at.
* :mod:`.regression_bias`: the regressions' bias, from their difference to a
  less biased reference of the same input.
* :mod:`.gradient_geometry`: the gradient's share of the DIC noise (its
  tangent plane and the sample position).
* :mod:`.strain`: the strain's std (probe covariance of the tensor, RMS of
  the max principal strain at the estimated tensor) and its noise floor.

The model is stated in docs/method.md (Uncertainty). The initialiser imports
none of its modules.
"""
