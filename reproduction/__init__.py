r"""Reproduce the simulation results of the paper's Section 4 with one command.

``coopnav reproduce --out DIR`` (or :func:`reproduce`) simulates the scenario of Section 4.1
(:mod:`coopnav_env.reproduction.scenario`), runs the navigation core of :mod:`coopnav_env.nav`
on it and writes to ``DIR``:

* ``results.json`` - every reproduced number, the published one beside it, the qualitative
  claims checked, exclusions and (under ``"timing"``) the run time;
* ``report.md`` - a self-contained report: what was simulated, reproduced vs published values,
  the figures, a sensitivity table and where and why the numbers differ;
* ``fig*.png`` - the analogues of Figures 6-12 and Table 2;
* ``config.json`` - the configuration and seed, loadable with ``--config``.

Studies
-------
``main``         5 UAVs, canyon ``h/d = sqrt(3)``, no differential correction: Table 1, the
                 probability of a 3-D error below 3 m (SDT and DDT), Figures 7-9.
``los``          the canyon UAV's number of line-of-sight satellites varied (by ``h/d`` or by
                 thinning), with and without differential correction: Figures 10-11.
``swarm``        swarm size N = 2 ... 50, with and without differential correction: Table 2.
``rel_error``    relative-position error varied, proposed vs master-slave: Figure 12.
``sensitivity``  the main results under the alternatives of the choices the paper leaves open.

Definitions
-----------
All statistics are of the canyon UAV's position error in the ENU frame of the formation origin,
pooled over epochs and noise realisations (``n_samples`` per epoch). A realisation in which the
UAV cannot locate itself (``status != NavStatus.OK``, or by default a standalone fix with PDOP
above ``ReproduceConfig.max_pdop = 10``) is excluded, as the paper excludes the epochs in which
the UAV "failed to locate itself"; a comparison between two methods uses only the realisations
where both have a fix.

Defaults
--------
The defaults reproduce the paper best among the configurations compared (the committed report,
``docs/reproduction/report.md``, shows the alternatives): the PDOP mask above, and the user error
of Eq. 8 without its iono-free factor (``PaperScenario.iono_free = False``), which is what the
paper's Table 2 (33 % with differential correction below 56 % without at N = 2) and Figure 12b
imply although Eq. 8 prints the factor. ``coopnav reproduce --quick`` is a smoke run, not the
reproduction, and its report says so.

* Mean: mean absolute error per axis. The paper's "Mean" is evidently that: its ratio to the
  STD is 0.77-0.80 in every row of Table 1, where a zero-mean Gaussian gives sqrt(2/pi) = 0.80
  (and a mixture of Gaussians a little less); a signed mean would be near zero.
* STD: standard deviation of the pooled errors (Monte Carlo).
* SIG: ``sqrt(mean of H_ii)`` with ``H`` the solver's covariance in ENU (Eq. 23), averaged over
  the same realisations: the root mean square of the per-epoch sigmas, which is what the pooled
  STD estimates when the predicted covariance is right.
* Improvement: ``1 - SIG3D(coop) / SIG3D(standalone)`` with ``SIG3D = sqrt(SIG_E^2 + SIG_N^2 +
  SIG_U^2)``, the paper's definition as far as it can be recovered: Table 1's SIG columns give
  exactly the 57.53 % of Table 2 (N = 5, no differential correction), the STD columns 57.43 %,
  the Mean columns 56.0 %. We also report the Monte Carlo counterpart
  ``1 - RMS3D(coop) / RMS3D(standalone)``; the two agree when the covariance is right.

Modules, one job each
---------------------
``scenario``    the Section 4.1 scenario: formation, canyon mask, constellations, errors
``config``      :class:`ReproduceConfig` and the published values (:data:`PUBLISHED`)
``simulation``  every method on every epoch of every study; the statistics of pooled errors
``tables``      reproduced vs published numbers, and the paper's claims checked
``figures``     the PNG figures
``report``      the Markdown report
``cli``         :func:`reproduce` (writes everything) and the ``coopnav reproduce`` command
"""

from coopnav_env.old_names import redirect as _redirect_old_name

# imported as 'reproduction' (a source checkout): becomes 'coopnav_env.reproduction'
_redirect_old_name(__name__)

from coopnav_env.reproduction.cli import build_config, reproduce  # noqa: E402
from coopnav_env.reproduction.config import PUBLISHED, ReproduceConfig  # noqa: E402
from coopnav_env.reproduction.scenario import PaperEpoch, PaperScenario  # noqa: E402
from coopnav_env.reproduction.simulation import run_studies, simulate_epoch  # noqa: E402

__all__ = [
    "PUBLISHED",
    "PaperEpoch",
    "PaperScenario",
    "ReproduceConfig",
    "build_config",
    "reproduce",
    "run_studies",
    "simulate_epoch",
]
