"""Temporal filtering of camera poses on SE(3): an adaptive constant-velocity (alpha-beta) filter.

The state is the camera's position p (world, metres), orientation R
(world_from_camera rotation) and their velocities v (m/s), w (rad/s, world
frame). Each frame the state is predicted with constant velocity and pulled
toward the measurement by a gain alpha that adapts like the One-Euro filter:
the cutoff frequency grows with the camera's speed (rad/s, translation
counted as the angle it subtends at the scene distance) and with innovation
beyond three times its usual size (a sudden start or stop), so a still camera
is smoothed hard while a moving one is followed closely. Velocity is
corrected with the Benedict-Bordner gain beta = alpha^2 / (2 - alpha); with
the velocity in the prediction, constant motion is followed without lag.

Given the target's centre, the innovation is split in two. The orbit mode, the
camera turning about the target's centre (moving across the line of sight to it
while turning to keep it in place in the image), changes only the target's
perspective, which a small target shows worst: a lone 6 cm marker's tilt noise
moves the camera by millimetres along it, where a camera turn or a move along
the line of sight shows as whole pixels. That mode gets its own cutoff, from
its own speed (the camera's velocity across the line of sight; a hand-held
camera's turning, which raises the other modes' cutoff, does not raise it), and
never a higher gain than the rest.
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def _exp(w: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(w, dtype=np.float64).reshape(3, 1))[0]


def _log(R: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.ascontiguousarray(R, dtype=np.float64))[0].ravel()


class PoseFilter:
    """Adaptive constant-velocity filter of `world_from_camera` poses.

    min_cutoff: cutoff frequency (Hz) when the motion is fully predicted; lower = smoother.
    beta: how fast the cutoff rises with the unexplained speed (Hz per rad/s); higher = less lag.
    max_gap: seconds without a measurement after which the filter restarts from the next one.
    jump: unexplained motion (radians, translation counted as metres / scene distance) that restarts the filter.
    max_velocity_alpha: cap on the gain used to derive the velocity correction (robustness to noisy frames).
    """

    def __init__(self, min_cutoff: float = 1.0, beta: float = 10.0, max_gap: float = 0.5, jump: float = 0.5,
                 max_velocity_alpha: float = 0.4):
        if min_cutoff <= 0 or beta < 0 or max_gap <= 0 or jump <= 0:
            raise ValueError("filter parameters: min_cutoff, max_gap and jump must be positive and beta >= 0")
        self.min_cutoff = float(min_cutoff)
        self.beta = float(beta)
        self.max_gap = float(max_gap)
        self.jump = float(jump)
        self.max_velocity_alpha = float(max_velocity_alpha)
        self.reset()

    def reset(self) -> None:
        self.t = None
        self.p = self.R = None
        self.v = np.zeros(3)
        self.w = np.zeros(3)
        self.n = 0
        self.noise2 = None  # running mean of the squared innovation (rad^2)

    @property
    def initialised(self) -> bool:
        return self.t is not None

    def predict(self, t: float) -> np.ndarray | None:
        """Predicted world_from_camera at time t (None before the first measurement or after a long gap)."""
        if self.t is None or t - self.t > self.max_gap:
            return None
        dt = max(t - self.t, 0.0)
        T = np.eye(4)
        T[:3, :3] = _exp(self.w * dt) @ self.R
        T[:3, 3] = self.p + self.v * dt
        return T

    def update(self, world_from_camera: np.ndarray, t: float, distance: float = 1.0,
               sigma: float | None = None, weight: float = 1.0, centre: np.ndarray | None = None) -> np.ndarray:
        """Filtered pose after the measurement `world_from_camera` at time t (seconds).

        `distance` (metres, the scene depth) converts translation to the angle it subtends. `sigma`
        (radians, optional): the measurement's own noise; an innovation many sigmas large is motion the
        filter has not caught up with, and the gain rises toward 1 - (3 sigma / innovation)^2 so that a
        precise measurement is never lagged behind. `weight` (0..1) scales the gain for a measurement
        known to be poor (motion-smeared markers): the prediction counts for more. `centre` (world
        point, metres; optional): the centre of the target the measurement comes from; with it the orbit
        mode about that point is filtered with its own gain (module docstring, `_orbit_gains`).
        """
        Rm = world_from_camera[:3, :3]
        pm = world_from_camera[:3, 3]
        pred = self.predict(t)
        dt = 0.0 if self.t is None else t - self.t
        if pred is None or dt <= 0:
            return self._restart(world_from_camera, t)
        e_p = pm - pred[:3, 3]
        e_r = _log(Rm @ pred[:3, :3].T)
        d = max(float(distance), 1e-3)
        m = float(np.linalg.norm(e_r) + np.linalg.norm(e_p) / d)
        if m > self.jump:
            return self._restart(world_from_camera, t)
        if self.noise2 is None:
            self.noise2 = m * m
        surprise = max(0.0, m - 3.0 * math.sqrt(self.noise2))
        self.noise2 = 0.9 * self.noise2 + 0.1 * min(m * m, 9.0 * self.noise2 + 1e-12)
        speed = float(np.linalg.norm(self.w) + np.linalg.norm(self.v) / d)
        fc = self.min_cutoff + self.beta * (speed + surprise / dt)
        a = self._gain(fc, dt, m, sigma, weight)
        b = self._velocity_gain(a)
        dp, dr, dv, dw = a * e_p, a * e_r, b * e_p, b * e_r
        if centre is not None and self.n >= 1:
            orbit = self._orbit_steps(pred[:3, 3] - np.asarray(centre, dtype=np.float64), e_p, e_r,
                                      (dt, m, sigma, weight, surprise, a, b))
            if orbit is not None:
                dp, dr, dv, dw = orbit
        self.p = pred[:3, 3] + dp
        self.R = _exp(dr) @ pred[:3, :3]
        self.n += 1
        if self.n == 1:
            # second measurement: start the velocity from the finite difference instead of from rest,
            # shrunk by how much of that difference the two measurements' noise (variance 2 sigma^2)
            # explains (Wiener: signal^2 / (signal^2 + noise^2)); a still camera's noisy pair must not
            # fling the first frames off, while a precise measurement's difference is taken as it is
            k = 1.0 if sigma is None or m <= 0 else max(0.0, 1.0 - 2.0 * float(sigma) ** 2 / (m * m))
            a0 = max(0.5, k)   # with no motion to follow, the mean of the two is the best position
            self.v, self.w = k * e_p / dt, k * e_r / dt
            self.p = pred[:3, 3] + a0 * e_p
            self.R = _exp(a0 * e_r) @ pred[:3, :3]
        else:
            self.v = self.v + dv / dt
            self.w = self.w + dw / dt
        self.t = t
        return self.pose()

    def _orbit_steps(self, off: np.ndarray, e_p: np.ndarray, e_r: np.ndarray, gains_args: tuple):
        """The update's steps (dp, dr, dv, dw) with the orbit mode about the target's centre (`off`: the
        predicted camera position from it, metres) given its own gains (`_orbit_gains(u, dist, *gains_args)`,
        whose last two are the plain gains a, b); None at the centre itself."""
        dist = float(np.linalg.norm(off))
        if dist <= 1e-6:
            return None
        a, b = gains_args[-2], gains_args[-1]
        u = off / dist
        # the orbit mode's part of the innovation: the camera's move across the line of sight and
        # the turn w_o = u x e_perp / dist that keeps the centre where it was in the image
        e_perp = e_p - (e_p @ u) * u
        w_o = np.cross(u, e_perp) / dist
        ao, bo = self._orbit_gains(u, dist, *gains_args)
        return (a * (e_p - e_perp) + ao * e_perp, a * (e_r - w_o) + ao * w_o,
                b * (e_p - e_perp) + bo * e_perp, b * (e_r - w_o) + bo * w_o)

    def _gain(self, fc: float, dt: float, m: float, sigma: float | None, weight: float) -> float:
        """Position/orientation gain for cutoff `fc` (Hz) over `dt` (s), raised toward 1 - (3 sigma / m)^2
        for an innovation `m` (rad) many sigmas large, scaled by the measurement's `weight`."""
        a = 1.0 / (1.0 + 1.0 / (2.0 * math.pi * fc) / dt)
        if sigma is not None and m > 3.0 * sigma:
            a = max(a, 1.0 - (3.0 * sigma / m) ** 2)
        return a * min(max(float(weight), 0.0), 1.0)

    def _velocity_gain(self, a: float) -> float:
        """Benedict-Bordner velocity gain from a capped alpha: one noisy frame must not fling the
        prediction (and with it the choice between a marker's two IPPE solutions) far off."""
        av = min(a, self.max_velocity_alpha)
        return av * av / (2.0 - av)

    def _orbit_gains(self, u: np.ndarray, dist: float, dt: float, m: float, sigma: float | None, weight: float,
                     surprise: float, a: float, b: float) -> tuple[float, float]:
        """(position, velocity) gains of the orbit mode about a centre `dist` metres away along `u`
        (unit, from the centre to the camera).

        Its cutoff rises with the orbit's own speed: the camera's velocity across the line of sight, as
        the angle it sweeps about the centre plus the turn that goes with it (2 |v_perp| / dist, rad/s,
        counted the way `speed` counts a move and a turn), and with the same surprise as the rest; never
        above the rest's gains (a, b). In the first frames after a (re)start its velocity is unknown: the
        gains are then at least those of a least-squares straight-line fit to the measurements so far
        (2 (2k - 1) / (k (k + 1)) and 6 / (k (k + 1)) at the k-th measurement), capped at a and b, so
        a camera already moving is caught up with as fast as before."""
        v_perp = self.v - (self.v @ u) * u
        fc = self.min_cutoff + self.beta * (2.0 * float(np.linalg.norm(v_perp)) / dist + surprise / dt)
        ao = min(self._gain(fc, dt, m, sigma, weight), a)
        bo = self._velocity_gain(ao)
        k = self.n + 2   # this measurement's number since the restart (the first two started the state)
        ao = max(ao, min(2.0 * (2 * k - 1) / (k * (k + 1)), a))
        bo = max(bo, min(6.0 / (k * (k + 1)), b))
        return ao, bo

    def pose(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.p
        return T

    def _restart(self, world_from_camera: np.ndarray, t: float) -> np.ndarray:
        self.t = float(t)
        self.n = 0
        self.noise2 = None
        self.R = world_from_camera[:3, :3].copy()
        self.p = world_from_camera[:3, 3].copy()
        self.v = np.zeros(3)
        self.w = np.zeros(3)
        return self.pose()
