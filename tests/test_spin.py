"""The plant's bounded spin before a blocking wait (sitl/spin.py): hits, misses and the
back-off after misses, counted (no wall-clock figure is asserted)."""

import pytest

from sitl.spin import BACKOFF_MAX, SpinWait


def test_a_zero_budget_never_spins():
    calls = []
    w = SpinWait(0.0)
    assert not w.until(lambda: calls.append(1))
    assert calls == [] and w.spins == 0


def test_the_spin_ends_when_the_input_is_there():
    answers = iter([False, False, True])
    w = SpinWait(60.0)      # (never spent: the input comes on the third look)
    assert w.until(lambda: next(answers))
    assert (w.spins, w.hits) == (1, 1)


def test_misses_back_off_doubling_and_a_hit_resets_it():
    w = SpinWait(1e-6)
    spun = []
    for _ in range(40):
        before = w.spins
        assert not w.until(lambda: False)
        spun.append(w.spins - before)
    # spin, skip 1, spin, skip 2, spin, skip 4, spin, skip 8, spin, skip 16, ...
    assert [i for i, s in enumerate(spun) if s] == [0, 2, 5, 10, 19, 36]
    w._skip = 0
    assert w.until(lambda: True)        # a hit: the next miss skips one wait again
    assert not w.until(lambda: False)
    assert w._skip == 1
    assert BACKOFF_MAX >= 32


def test_a_negative_budget_is_refused():
    with pytest.raises(ValueError, match="spin budget"):
        SpinWait(-1.0)
