"""The paper's Tables 1-5, transcribed from ``shared/paper/paper.txt`` (the OCR'd text).

Values are as printed, in the paper's units: J (eqs. 5 and 17) dimensionless, J_u and
J_u,tau (sum of |input|) in N and rad/s^2 as the paper sums them, and J_e (sum of the
error norm) apparently in **centimetres** (NOTES.md; Table 1 defines e = [30 cm, 0] -
[z, z_dot], and the outdoor values are far too small for metres summed every 10 ms over
minutes).  Its J_u also seems to exclude most of the hover thrust (Table 1's 692 N over
60 s at 100 Hz would be a 0.1 N mean thrust).  ``None`` is a cell printed as "-" or
empty.

Tables 3 and 5 ("error standard deviation") have lost their numbers in the text; only
the prose survives: Table 3 "the suboptimal nonlinear controller presents lower
dispersion around 0.18 m", Table 5 "the controller that induces a lower error mean is
the suboptimal nonlinear controller with less dispersion".

Mapping to this project's metrics (:data:`gcs.metrics.METRICS`): Table 1's J_e is
against the final set point (erratum 11), our ``J_e_setpoint``; the outdoor J_e is our
``J_e``; the outdoor J_{u,tau_phi,tau_theta,tau_psi} is our ``J_u_all``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PaperRow", "PaperTable", "PAPER_TABLES", "PAPER_CONTROLLERS", "PAPER_TRENDS", "paper_table"]

#: The paper's controllers, in its column order (it did not fly the literal NLSOC law separately).
PAPER_CONTROLLERS = ("nlsoc", "loc", "pd")


@dataclass(frozen=True)
class PaperRow:
    """One printed row.

    Attributes
    ----------
    printed : str
        The row's label as printed.
    metric : str
        Our metric key it corresponds to.
    unit : str
        The paper's unit, as far as it can be told.
    sim, exp : dict
        Controller -> value (``None``: not printed); simulation and experiment columns.
    """

    printed: str
    metric: str
    unit: str
    sim: dict
    exp: dict


@dataclass(frozen=True)
class PaperTable:
    """One of Tables 1-5.

    Attributes
    ----------
    number : int
    title : str
        The caption, shortened.
    experiment : str
        Our experiment name.
    kind : {"mean", "std"}
        Means over the runs (Tables 1, 2, 4) or their standard deviations (3, 5).
    rows : tuple of PaperRow
    note : str
        What the text says when the numbers are lost.
    """

    number: int
    title: str
    experiment: str
    kind: str
    rows: tuple[PaperRow, ...]
    note: str = ""


def _r(printed, metric, unit, sim, exp) -> PaperRow:
    return PaperRow(printed, metric, unit, dict(zip(PAPER_CONTROLLERS, sim, strict=True)),
                    dict(zip(PAPER_CONTROLLERS, exp)))


PAPER_TABLES: dict[int, PaperTable] = {
    1: PaperTable(1, "Performance and energy, indoor 4-DOF rig (altitude ramp to 30 cm in 15 s, 40 s horizon then PD)",
                  "indoor-4dof", "mean", (
                      _r("Jz given by (5) and (18)", "J", "-", (11860.4, 560.89, None), (15214.236, 490.791, None)),
                      _r("J_u", "J_u", "N (sum |u|)", (1221.5, 692.4, 1121.0), (1732.648, 757.023, 1396.423)),
                      _r("J_e", "J_e_setpoint", "cm (apparently)", (23869.0, 26869.0, 24365.0),
                         (16108.471, 20675.477, 28089.648)),
                  )),
    2: PaperTable(2, "Performance and energy, outdoor altitude (2 m set point, 10 min horizon, 10 runs)",
                  "outdoor-altitude", "mean", (
                      _r("Jz given by (5)", "J", "-", (1.28e7, 3.79e8, None), (1.35e7, 4.47e8, None)),
                      _r("J_{u,tau_phi,tau_psi,tau_theta}", "J_u_all", "N + rad/s^2 (sum of |inputs|)",
                         (5268.0, 1181.80, 6304.0), (8967.7, 8818.3, 11553.57)),
                      _r("J_e", "J_e", "cm (apparently)", (184.0, 253.0, 236.0), (738.31, 914.3, 1090.0)),
                  )),
    3: PaperTable(3, "Error standard deviation over the runs, outdoor altitude", "outdoor-altitude", "std", (),
                  note="numbers lost in the text; it says NLSOC has the lowest dispersion, 'around 0.18 m'"),
    4: PaperTable(4, "Performance and energy, outdoor circle (1 m radius at 1.5 m, 60 s horizon, 10 runs)",
                  "outdoor-circle", "mean", (
                      _r("J_{u,tau_phi,tau_psi,tau_theta}", "J_u_all", "N + rad/s^2 (sum of |inputs|)",
                         (3165.5, 1614.0, 2269.3), (5415.2, 5374.5, 6072.6)),
                      _r("J_e", "J_e", "cm (apparently)", (1351.7, 1758.1, 1549.13), (1905.78, 2332.04, 2467.47)),
                  )),
    5: PaperTable(5, "Error standard deviation over the runs, outdoor circle", "outdoor-circle", "std", (),
                  note="numbers lost in the text; it says NLSOC has the lowest error mean 'with less dispersion'"),
}

#: The paper's claims, as its text states them (used by :mod:`gcs.campaign.trends`).
PAPER_TRENDS = (
    "NLSOC has the lowest tracking error (Tables 1, 2, 4)",
    "LOC uses the least energy (Tables 1, 2, 4)",
    "PD uses the most energy (the conclusions; Tables 2 and 4 experiments)",
    "NLSOC has the smallest error dispersion over the runs (Tables 3, 5)",
)


def paper_table(number: int) -> PaperTable:
    """Table ``number`` (1-5)."""
    return PAPER_TABLES[number]
