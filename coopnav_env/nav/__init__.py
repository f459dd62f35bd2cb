"""Navigation: standalone WLS, virtual-centroid cooperative solver (SDT/DDT), master-slave,
integrity monitoring (RAIM FDE and protection levels)."""

from coopnav_env.nav.cooperative import (
    CooperativeSolution,
    MasterSlaveSolution,
    solve_cooperative,
    solve_cooperative_samples,
    solve_master_slave,
)
from coopnav_env.nav.integrity import (
    IntegrityRates,
    IntegrityResult,
    IntegrityStatus,
    fde_cooperative,
    fde_standalone,
    integrity_rates,
)
from coopnav_env.nav.types import (
    PLAUSIBLE_RADIUS_M,
    WEAK_GEOMETRY_SIGMA_M,
    GnssObservations,
    NavStatus,
    RelativePositions,
    VirtualPoint,
    weak_geometry,
)
from coopnav_env.nav.wls import StandaloneSolution, pdop, solve_standalone

__all__ = [
    "PLAUSIBLE_RADIUS_M",
    "WEAK_GEOMETRY_SIGMA_M",
    "CooperativeSolution",
    "GnssObservations",
    "IntegrityRates",
    "IntegrityResult",
    "IntegrityStatus",
    "MasterSlaveSolution",
    "NavStatus",
    "RelativePositions",
    "StandaloneSolution",
    "VirtualPoint",
    "fde_cooperative",
    "fde_standalone",
    "integrity_rates",
    "pdop",
    "solve_cooperative",
    "solve_cooperative_samples",
    "solve_master_slave",
    "solve_standalone",
    "weak_geometry",
]
