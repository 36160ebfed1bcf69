"""Heat sources from the coupled fields: the local heat balance of a thin wall on the curved surface.

* :func:`surface_laplacian` (:mod:`.laplacian`): the Laplace–Beltrami operator
  of the temperature on the current surface, from a regression in the
  surface parameters, with its spacing chosen for the Laplacian and its
  standard uncertainty.
* :func:`laplacian_bias` (:mod:`.bias`): that regression's bias, estimated
  from the data, which :func:`with_bias` adds to the std.
* :func:`heat_balance` (:mod:`.balance`): ``s = ρc (Θ̇ + (Θ − Θ0)/τ) − k Δ_s Θ``
  and its terms with their standard uncertainties.
* :func:`loss_time_constant` (:mod:`.balance`): τ by least squares from a
  source-free window.

Units: mm, s, K, W/m³ (see ``docs/heat.md``).
"""

from .balance import HeatTerms, heat_balance, loss_time_constant
from .bias import laplacian_bias, with_bias
from .laplacian import Laplacian, laplace_beltrami, smooth_in_time, surface_laplacian

__all__ = ["Laplacian", "laplace_beltrami", "surface_laplacian", "smooth_in_time", "laplacian_bias", "with_bias",
           "HeatTerms", "heat_balance", "loss_time_constant"]
