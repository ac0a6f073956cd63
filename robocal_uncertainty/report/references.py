"""The reference paper the robot outputs compare with, named as outputs name it.

Outputs used to call it "the seed" ("Seed Table 2", "u seed/ours"), the word ``--seed`` and
"seed N" use for the random seed: a user could not tell which was meant. Outputs now name the
paper by its first author, with the full reference where it is first introduced.
"""

from __future__ import annotations

__all__ = ["PAPER_TEST_JOINTS_DEG", "ROBOT_PAPER", "ROBOT_PAPER_REFERENCE"]

ROBOT_PAPER = "Jiang et al."
"""Short name of the robot reference paper, e.g. ``Jiang et al. Table 2``."""

ROBOT_PAPER_REFERENCE = (
    "Jiang W., Li X., Luo Z., Yang L., Guo B., 'Uncertainty evaluation of calibration model of six DOF robot "
    "arm', Chinese Journal of Scientific Instrument, doi:10.19650/j.cnki.cjsi.J2209613"
)
"""Full reference of the robot paper (authors, title, journal, DOI)."""

PAPER_TEST_JOINTS_DEG: tuple[float, ...] = (-7.5005, -234.4840, -106.7448, -92.3875, -61.5425, 20.7451)
"""The robot paper's test configuration [deg], at which its Table 2 states the tool position."""
