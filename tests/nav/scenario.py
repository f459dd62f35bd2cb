"""A small, self-contained synthetic epoch for the navigation tests.

Deliberately independent of ``coopnav_env.gnss`` so that the navigation core is tested on its
own: satellites are placed by azimuth/elevation at GNSS distances from a site near Shanghai.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coopnav_env.nav import GnssObservations, RelativePositions

A = 6378137.0
E2 = 6.69437999014e-3
LAT, LON, ALT = 31.0252, 121.4337, 60.0


def geodetic_to_ecef(lat, lon, alt):
    lat, lon = np.radians(lat), np.radians(lon)
    n = A / np.sqrt(1 - E2 * np.sin(lat) ** 2)
    return np.array(
        [
            (n + alt) * np.cos(lat) * np.cos(lon),
            (n + alt) * np.cos(lat) * np.sin(lon),
            (n * (1 - E2) + alt) * np.sin(lat),
        ]
    )


def enu_rot(lat=LAT, lon=LON):
    la, lo = np.radians(lat), np.radians(lon)
    return np.array(
        [
            [-np.sin(lo), np.cos(lo), 0.0],
            [-np.sin(la) * np.cos(lo), -np.sin(la) * np.sin(lo), np.cos(la)],
            [np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)],
        ]
    )


def sig_tropo(el):
    return 0.12 * 1.001 / np.sqrt(0.002001 + np.sin(np.radians(el)) ** 2)


def sig_user(el):
    mp = 0.13 + 0.53 * np.exp(-el / 10)
    nz = 0.15 + 0.43 * np.exp(-el / 6.9)
    return 2.98 * np.sqrt(mp**2 + nz**2)


@dataclass
class Scenario:
    pos_ecef: np.ndarray  # (N, 3)
    sv_ecef: np.ndarray  # (S, 3)
    system: np.ndarray
    visible: np.ndarray  # (N, S)
    el_deg: np.ndarray  # (N, S)
    az_deg: np.ndarray
    sigma_user: np.ndarray
    sigma_common: np.ndarray
    clock: np.ndarray  # (N, n_sys)
    sigma_d: np.ndarray  # (N, N) per-axis relative error std (ENU isotropic)
    rot: np.ndarray

    @property
    def range(self):
        return np.linalg.norm(self.sv_ecef[None] - self.pos_ecef[:, None], axis=-1)

    def observations(self, rng=None, noise=True, common=None, user=None):
        n, s = self.visible.shape
        pr = self.range + self.clock[:, self.system]
        if noise:
            if common is None:
                common = rng.standard_normal(s) * self.sigma_common
            if user is None:
                user = rng.standard_normal((n, s)) * self.sigma_user
            pr = pr + common[None] + user
        pr = np.where(self.visible, pr, np.nan)
        return GnssObservations(
            pr_m=pr,
            sv_ecef_m=self.sv_ecef,
            system=self.system,
            sigma_user_m=self.sigma_user,
            sigma_common_m=self.sigma_common,
            el_deg=self.el_deg,
        )

    def relative(self, rng=None, noise=True, cov_enu=None):
        n = self.pos_ecef.shape[0]
        if cov_enu is None:
            cov_enu = self.sigma_d[:, :, None, None] ** 2 * np.eye(3)
        cov_ecef = np.einsum("ji,abjk,kl->abil", self.rot, cov_enu, self.rot)
        true = self.pos_ecef[None, :, :] - self.pos_ecef[:, None, :]
        eps = np.zeros((n, n, 3))
        if noise:
            root = np.linalg.cholesky(cov_ecef + 1e-18 * np.eye(3))
            z = rng.standard_normal((n, n, 3))
            e = np.einsum("abij,abj->abi", root, z)
            iu = np.triu_indices(n, 1)
            eps[iu] = e[iu]
            eps[(iu[1], iu[0])] = -e[iu]
        for i in range(n):
            cov_ecef[i, i] = 0.0
        return RelativePositions(
            rel_ecef_m=true + eps, cov_ecef_m2=cov_ecef, available=np.ones((n, n), dtype=bool)
        )


def make_scenario(
    n_uav=5,
    n_sv=16,
    seed=0,
    spread_m=40.0,
    differential=False,
    sigma_d=0.5,
    canyon_uav=None,
    canyon_hd=3**0.5,
    colocated=False,
    max_open=None,
):
    """Swarm of ``n_uav`` UAVs, ``n_sv`` satellites (alternating GPS/BDS) in the sky.

    ``canyon_uav``: index of a UAV behind the paper's analytic mask (Eq. 25, street along N).
    ``max_open``: keep at most this many highest satellites for the UAVs in open sky.
    """
    rng = np.random.default_rng(seed)
    origin = geodetic_to_ecef(LAT, LON, ALT)
    rot = enu_rot()
    enu = rng.uniform(-spread_m, spread_m, (n_uav, 3)) * [1, 1, 0.2]
    if colocated:
        enu[:] = 0.0
    pos = origin + enu @ rot
    az = rng.uniform(0, 360, n_sv)
    el = np.degrees(np.arcsin(rng.uniform(np.sin(np.radians(8)), 0.98, n_sv)))
    d = np.stack(
        [
            np.cos(np.radians(el)) * np.sin(np.radians(az)),
            np.cos(np.radians(el)) * np.cos(np.radians(az)),
            np.sin(np.radians(el)),
        ],
        axis=1,
    )
    sv = origin + 2.2e7 * d @ rot
    system = (np.arange(n_sv) % 2).astype(int)
    diff = sv[None] - pos[:, None]
    u_enu = diff @ rot.T
    u_enu /= np.linalg.norm(u_enu, axis=-1, keepdims=True)
    el_q = np.degrees(np.arcsin(u_enu[..., 2]))
    az_q = np.degrees(np.arctan2(u_enu[..., 0], u_enu[..., 1])) % 360
    visible = np.ones((n_uav, n_sv), dtype=bool)
    if max_open is not None:
        order = np.argsort(-el)
        keep = np.zeros(n_sv, dtype=bool)
        keep[order[:max_open]] = True
        visible &= keep[None]
    if canyon_uav is not None:
        mask = np.degrees(np.abs(np.arctan(canyon_hd * np.sin(np.radians(az_q[canyon_uav])))))
        visible[canyon_uav] = el_q[canyon_uav] > mask
    sig_c = np.zeros(n_sv) if differential else np.sqrt(1.0 + sig_tropo(el) ** 2)
    clock = rng.uniform(-3e4, 3e4, (n_uav, 2))
    return Scenario(
        pos_ecef=pos,
        sv_ecef=sv,
        system=system,
        visible=visible,
        el_deg=el_q,
        az_deg=az_q,
        sigma_user=sig_user(el_q),
        sigma_common=sig_c,
        clock=clock,
        sigma_d=np.full((n_uav, n_uav), sigma_d),
        rot=rot,
    )
