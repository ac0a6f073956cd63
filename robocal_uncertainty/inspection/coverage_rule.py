"""The rule that says whether a coverage study verifies the 95 % intervals, per study cell.

One rule for every study (the stored ones the report quotes and a study run for a user's own
cloud, :mod:`.coverage_study`): a cell (one parameter in one scenario family) is verified when
its study has at least :data:`MIN_STUDY_SCANS` usable scans, the measured coverage is at least
the lower limit of :data:`COVERAGE_TOLERANCE` (the 92 % floor), and the exact one-sided binomial
test of "coverage >= 95 %" is not rejected at :data:`BINOMIAL_LEVEL`, the p-values
Holm-adjusted over the study's cells (:func:`holm_adjusted`) where a study has several.
It lives here, not in the report, so that the report only renders a verdict computed once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

from scipy.stats import binom

__all__ = [
    "BINOMIAL_LEVEL",
    "COVERAGE_TOLERANCE",
    "MIN_STUDY_SCANS",
    "FamilyCounts",
    "FamilyCoverage",
    "binomial_tail",
    "coverage_verified",
    "family_cells",
    "holm_adjusted",
]

COVERAGE_TOLERANCE = (0.92, 0.98)
"""95 ± 3 %, the tolerance a 95 % coverage claim is held to here. A measured coverage below the
lower limit is never verified; one above the upper limit is conservative (the interval is wider
than it needs to be) and is said so."""

MIN_STUDY_SCANS = 53
"""Fewest scans (unflagged, for a family) a study needs before it can verify a coverage: the
binomial standard uncertainty at 95 %, sqrt(0.95·0.05/N), is then at most 3 %, the tolerance."""

BINOMIAL_LEVEL = 0.05
"""Level of the exact one-sided binomial test of "coverage >= 95 %" (per cell in the demo study,
family-wise over the cells of a scenario-family study: :func:`holm_adjusted`)."""


def binomial_tail(inside: int, scans: int) -> float:
    """P(X <= inside) for X ~ Binomial(scans, 0.95): the one-sided p-value of "coverage >= 95 %"."""
    return float(binom.cdf(inside, scans, 0.95))


def holm_adjusted(p_values: Sequence[float]) -> tuple[float, ...]:
    """Holm's step-down adjusted p-values (nan stays nan and does not count as a test).

    With m tests, sorted p_(1) <= ... <= p_(m): adjusted p_(i) = max over k <= i of
    min(1, (m - k + 1) p_(k)). Rejecting where the adjusted p-value is at most a level keeps the
    probability of rejecting any true hypothesis at most that level, whatever the dependence
    between the tests (the nine parameters of a family share its scans).
    """
    values = [float(p) for p in p_values]
    order = sorted((j for j, p in enumerate(values) if math.isfinite(p)), key=lambda j: values[j])
    adjusted = [math.nan] * len(values)
    running = 0.0
    for rank, j in enumerate(order):
        running = max(running, min(1.0, (len(order) - rank) * values[j]))
        adjusted[j] = running
    return tuple(adjusted)


def coverage_verified(inside: int, scans: int, *, p_value: float | None = None) -> bool:
    """Whether a study in which `inside` of `scans` intervals held the truth verifies 95 % coverage.

    Verified when the study has at least :data:`MIN_STUDY_SCANS` scans, the measured coverage is at
    least the lower limit of :data:`COVERAGE_TOLERANCE` (92 %), and the exact one-sided binomial
    test does not reject a coverage of at least 95 %: ``p_value > BINOMIAL_LEVEL``, where
    ``p_value`` is :func:`binomial_tail` of the cell unless given (a family study passes the
    cell's :func:`holm_adjusted` one). The scan count keeps a small study (38 scans: one miss is
    2.6 %) from verifying anything; the test keeps a large one from verifying a coverage that is
    92.5 % but significantly below 95 %.
    """
    if scans < MIN_STUDY_SCANS:
        return False
    if inside / scans < COVERAGE_TOLERANCE[0]:
        return False
    return (binomial_tail(inside, scans) if p_value is None else p_value) > BINOMIAL_LEVEL


class FamilyCoverage(NamedTuple):
    """Coverage of one parameter's 95 % interval (method ``denoised``) in one scenario family."""

    scans: int
    """Scans of the family."""
    flagged: int
    """Scans the residual check flagged."""
    inside: int
    """Unflagged scans whose interval held the truth."""
    inside_all: int
    """All scans whose interval held the truth (flagged ones included)."""
    p_holm: float = math.nan
    """Holm-adjusted p-value of "coverage >= 95 %" over the study's cells (:func:`holm_adjusted`)."""

    @property
    def coverage(self) -> float:
        """Coverage over the unflagged scans (nan when all were flagged)."""
        kept = self.scans - self.flagged
        return self.inside / kept if kept else math.nan

    @property
    def u(self) -> float:
        """Binomial standard uncertainty of :attr:`coverage` at 95 %."""
        kept = self.scans - self.flagged
        return math.sqrt(0.95 * 0.05 / kept) if kept else math.nan

    @property
    def consistent(self) -> bool:
        """:func:`coverage_verified` over the unflagged scans, at the Holm-adjusted p-value."""
        return coverage_verified(self.inside, self.scans - self.flagged, p_value=self.p_holm)


FamilyCounts = tuple[int, int, tuple[int, ...], tuple[int, ...]]
"""One family's counts: (scans, flagged, inside per parameter among the unflagged, inside among all)."""


def family_cells(counts: Mapping[str, FamilyCounts], parameters: Sequence[str]) -> dict[str, dict[str, FamilyCoverage]]:
    """A family study's counts as cells, each with its Holm-adjusted p-value over the whole study.

    Parameters
    ----------
    counts : mapping
        Per family, :data:`FamilyCounts` (the per-parameter tuples in `parameters` order).
    parameters : sequence of str
        Parameter names.

    Returns
    -------
    dict
        ``cells[family][parameter]``; a family whose scans were all flagged has no test (nan p-value).
    """
    cells = [
        (family, name, scans, flagged, kept[j], every[j])
        for family, (scans, flagged, kept, every) in counts.items()
        for j, name in enumerate(parameters)
    ]
    tails = [
        binomial_tail(inside, scans - flagged) if scans > flagged else math.nan
        for _, _, scans, flagged, inside, _ in cells
    ]
    study: dict[str, dict[str, FamilyCoverage]] = {family: {} for family in counts}
    for (family, name, scans, flagged, inside, inside_all), p_holm in zip(cells, holm_adjusted(tails)):
        study[family][name] = FamilyCoverage(scans, flagged, inside, inside_all, p_holm)
    return study
