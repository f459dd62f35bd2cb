"""coopnav: cooperative GNSS navigation for UAV swarms in urban canyons.

Sub-packages
------------
``coopnav_env.gnss``   frames, constellations, error models and pseudorange simulation.
``coopnav_env.nav``    standalone WLS, virtual-centroid cooperative solver (SDT/DDT), master-slave.
``coopnav_env.sim``    the urban world: buildings, line of sight, canyon mask, swarm kinematics.
``coopnav_env.envs``   the PettingZoo parallel environment.
"""

__version__ = "0.1.0"
