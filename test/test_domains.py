"""ROS domain ids: a run picks one from its range, so processes given disjoint ranges never meet."""

import pytest

from ema_sim.errors import EmaError
from ema_sim.suite import DOMAIN_RANGE_ENV, domain_range, free_domain_id


def test_a_free_domain_id_stays_in_the_range_it_is_given(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(DOMAIN_RANGE_ENV, "51-100")
    assert domain_range() == (51, 100)
    assert {free_domain_id(seed) for seed in range(500)} == set(range(51, 101))
    monkeypatch.delenv(DOMAIN_RANGE_ENV)
    assert domain_range() == (1, 101)
    assert free_domain_id(0) == 1


@pytest.mark.parametrize("text", ["100-50", "a-b", "5", "0-300"])
def test_a_malformed_domain_range_is_one_clear_error(monkeypatch: pytest.MonkeyPatch, text: str) -> None:
    monkeypatch.setenv(DOMAIN_RANGE_ENV, text)
    with pytest.raises(EmaError, match=DOMAIN_RANGE_ENV):
        domain_range()
