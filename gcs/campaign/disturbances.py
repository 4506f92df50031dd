"""The seeded disturbances of a campaign's runs: a pure function of (campaign seed, experiment, run).

:func:`draw_disturbances` never looks at the controller, so every controller meets the same wind,
sensor noise and initial attitude in run ``i``, as in ``gcs sim``.  An outdoor run (the built-in
MAVLink SITL):

* the SITL's ``--seed`` (sensor noise, gusts), drawn as a 31-bit integer;
* wind ``--wind SPEED,DIR,GUST,TAU``: speed ``wind_scale x [sim.wind] mean_speed_m_s x
  U(0.5, 1.5)``, direction ``U(0, 360)`` deg, gust standard deviation
  ``wind_scale x gust_std_m_s``, correlation time ``gust_tau_s`` (the config's
  ``[sim.wind]``, which describes the paper's cross wind);
* initial attitude ``--start-attitude ROLL,PITCH,YAW``: roll and pitch ``U(-tilt, tilt)``,
  yaw ``U(-yaw, yaw)`` deg (resting on a slight slope, pointing a little off north).

The indoor rig (``sitl --rig 4dof``) has no wind and starts level on its stand: its runs vary
the seed (ultrasonic and IMU noise) only.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from gcs.campaign.errors import CampaignError

__all__ = ["Disturbances", "DisturbanceModel", "draw_disturbances"]


@dataclass(frozen=True)
class DisturbanceModel:
    """How large the drawn disturbances are (see the module docstring).

    Attributes
    ----------
    wind_scale : float
        Multiplies the config's ``[sim.wind]`` speed and gusts; 0 = calm air (the
        paper's simulations had no disturbances).
    tilt_deg : float
        Bound of the initial roll and pitch [deg].
    yaw_deg : float
        Bound of the initial yaw [deg].
    """

    wind_scale: float = 1.0
    tilt_deg: float = 2.0
    yaw_deg: float = 10.0


@dataclass(frozen=True)
class Disturbances:
    """The seed-dependent conditions of one run (the same for every controller).

    Attributes
    ----------
    seed : int
        The SITL's ``--seed`` (``gcs fly --seed``): sensor noise and gusts.
    wind : tuple of 4 float or None
        ``(speed m/s, direction deg, gust std m/s, gust tau s)``; None = calm.
    start_attitude_deg : tuple of 3 float or None
        ``(roll, pitch, yaw)``; None = level, pointing north.
    """

    seed: int
    wind: tuple[float, float, float, float] | None = None
    start_attitude_deg: tuple[float, float, float] | None = None

    def sitl_args(self) -> tuple[str, ...]:
        """The ``sitl`` options (without ``--seed``, which ``gcs fly --seed`` passes)."""
        out = []
        if self.wind is not None:
            out.append("--wind=" + ",".join(_num(v) for v in self.wind))
        if self.start_attitude_deg is not None:
            out.append("--start-attitude=" + ",".join(_num(v) for v in self.start_attitude_deg))
        return tuple(out)

    def to_json(self) -> dict:
        return {"seed": self.seed, "wind": list(self.wind) if self.wind else None,
                "start_attitude_deg": list(self.start_attitude_deg) if self.start_attitude_deg else None}


def _num(v: float) -> str:
    return f"{v:g}" if float(v).is_integer() else repr(float(v))


def _stream(name: str) -> int:
    """A stable integer for a name (``hash`` changes between interpreters)."""
    return zlib.crc32(name.encode())


def draw_disturbances(seed: int, experiment: str, run: int, *, mavlink: bool = True,
                      wind: tuple[float, float, float] = (0.0, 0.0, 2.0),
                      model: DisturbanceModel = DisturbanceModel()) -> Disturbances:
    """The disturbances of run ``run`` of ``experiment`` in a campaign seeded ``seed``.

    Parameters
    ----------
    seed : int
        Campaign seed (>= 0).
    experiment : str
    run : int
        Run index (>= 0).
    mavlink : bool
        The MAVLink SITL (wind and initial attitude apply); False for the indoor rig.
    wind : (mean speed m/s, gust std m/s, gust tau s)
        The config's ``[sim.wind]``.
    model : DisturbanceModel

    Returns
    -------
    Disturbances
        A pure function of the arguments; values are rounded (4 decimals) so that the
        command line carries them exactly.
    """
    if seed < 0 or run < 0:
        raise CampaignError("--seed", "", f"seed and run must be >= 0, got {seed}, {run}")
    rng = np.random.default_rng([seed, _stream(experiment), run])
    sitl_seed = int(rng.integers(0, 2**31 - 1))
    u = rng.uniform(size=5)  # always drawn, so the seed stream does not depend on the options
    if not mavlink:
        return Disturbances(sitl_seed)
    mean, gust, tau = wind
    speed = round(model.wind_scale * mean * (0.5 + u[0]), 4)
    blow = None
    if speed > 0 or model.wind_scale * gust > 0:
        blow = (speed, round(360.0 * u[1], 4), round(model.wind_scale * gust, 4), round(tau, 4))
    att = (round(model.tilt_deg * (2 * u[2] - 1), 4), round(model.tilt_deg * (2 * u[3] - 1), 4),
           round(model.yaw_deg * (2 * u[4] - 1), 4))
    return Disturbances(sitl_seed, blow, None if not any(att) else att)
