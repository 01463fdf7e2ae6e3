"""The one mean and 95 % confidence interval of every table, against textbook t quantiles."""

from __future__ import annotations

import math

import pytest

from trust_av.study.tables import _cell
from trust_av_common.stats import mean_ci95, t_quantile_975


@pytest.mark.parametrize(('dof', 'quantile'), [(1, 12.706), (2, 4.303), (4, 2.776),
                                               (19, 2.093), (30, 2.042), (1000, 1.962)])
def test_t_quantiles_match_the_tables(dof: int, quantile: float) -> None:
    assert t_quantile_975(dof) == pytest.approx(quantile, abs=5e-4)


def test_mean_ci95_by_hand() -> None:
    # 1, 2, 3, 4: mean 2.5, s = sqrt(5/3), sem = s / 2, half-width t(3) = 3.182 x sem.
    mean, half = mean_ci95([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5
    assert half == pytest.approx(3.1824 * math.sqrt(5 / 3) / 2, rel=1e-4)


def test_one_value_has_no_interval_and_tables_say_so() -> None:
    mean, half = mean_ci95([7.0])
    assert mean == 7.0 and math.isnan(half)
    assert _cell([7.0], 2) == '7.00 (n = 1)'
    assert _cell([1.0, 3.0], 1) == f'2.0 ± {t_quantile_975(1) * 1.0:.1f}'


def test_mean_ci95_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match='at least one value'):
        mean_ci95([])
    with pytest.raises(ValueError, match='not finite'):
        mean_ci95([1.0, math.nan])
    with pytest.raises(ValueError, match='degrees of freedom must be >= 1, got 0'):
        t_quantile_975(0)
