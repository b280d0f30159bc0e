"""The success-rate interval against values computed independently (statsmodels' proportion_confint
with method="wilson" gives these; written out here, not computed by the code under test)."""

import pytest

from so101.evaluate.stats import wilson_interval


@pytest.mark.parametrize(
    "successes, episodes, low, high",
    [(12, 20, 0.3866, 0.7812), (0, 10, 0.0, 0.2775), (100, 100, 0.9630, 1.0), (80, 100, 0.7112, 0.8667)],
)
def test_wilson_interval_matches_the_reference(successes, episodes, low, high):
    assert wilson_interval(successes, episodes) == pytest.approx((low, high), abs=1e-4)


def test_bad_counts_are_refused():
    with pytest.raises(ValueError):
        wilson_interval(11, 10)
