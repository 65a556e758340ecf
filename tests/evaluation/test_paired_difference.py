"""`evaluation/paired_difference.py`: the mean per-frame difference of two backends' errors and its
moving-block bootstrap interval."""

from __future__ import annotations

import numpy as np

from uareme_fusion.evaluation.paired_difference import paired_difference


def test_a_constant_difference_has_no_spread():
    b = np.linspace(1.0, 3.0, 50)
    out = paired_difference(b + 0.25, b)
    assert out["frames"] == 50
    assert np.allclose([out["mean"], out["low"], out["high"]], 0.25, atol=1e-12)


def test_independent_differences_give_the_textbook_interval():
    rng = np.random.default_rng(1)
    diff = 0.05 + rng.standard_normal(3000)
    out = paired_difference(diff, np.zeros_like(diff))
    half_width = 1.96 * diff.std() / np.sqrt(diff.size)  # 0.036
    assert out["low"] < out["mean"] < out["high"]
    assert abs(out["mean"] - diff.mean()) < 1e-12
    assert 0.75 * half_width < (out["high"] - out["low"]) / 2 < 1.25 * half_width


def test_correlated_differences_widen_the_interval():
    """AR(1) differences (lag-one correlation 0.8): the mean's std is sqrt((1 + 0.8) / (1 - 0.8)) = 3
    times the independent formula's; blocks of 10 frames keep the correlations within a block, with
    Bartlett weights: sqrt(1 + 2 sum_h<10 (1 - h/10) 0.8^h) = 2.3 times."""
    rng = np.random.default_rng(2)
    diff = np.zeros(2000)
    for k in range(1, diff.size):
        diff[k] = 0.8 * diff[k - 1] + 0.6 * rng.standard_normal()
    out = paired_difference(diff, np.zeros_like(diff))
    independent_half_width = 1.96 * diff.std() / np.sqrt(diff.size)
    assert 1.9 < (out["high"] - out["low"]) / 2 / independent_half_width < 2.8


def test_non_finite_frames_are_left_out_and_the_draws_repeat():
    rng = np.random.default_rng(3)
    a, b = rng.normal(1.0, 0.1, 40), rng.normal(1.0, 0.1, 40)
    a[5], b[7] = np.nan, np.inf
    out = paired_difference(a, b)
    assert out["frames"] == 38
    assert out == paired_difference(a, b)
    assert abs(out["mean"] - np.mean(np.delete(a - b, [5, 7]))) < 1e-12


def test_too_few_frames_for_a_block_or_none():
    out = paired_difference(np.array([1.0, 2.0]), np.array([0.5, 1.0]))
    assert out == {"mean": 0.75, "low": 0.75, "high": 0.75, "frames": 2}
    assert paired_difference(np.array([np.nan]), np.array([1.0]))["frames"] == 0
