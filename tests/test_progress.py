"""The one definition of progress (core.progress) and its two users."""

import numpy as np
import pytest

from swarmpark import metrics
from swarmpark.control.nav.params import DeadlockParams, FieldParams
from swarmpark.core.progress import (
    NAV_HEADING_LEVER_M,
    REPORT_HEADING_LEVER_M,
    REPORT_PROGRESS_M,
    made_progress,
    remaining_m,
)


def test_remaining_counts_heading_at_the_lever():
    assert remaining_m(1.0, 0.5, 0.3) == pytest.approx(1.15)
    assert remaining_m(np.array([0.0, 2.0]), np.array([np.pi, 0.0]), 0.5) == pytest.approx(
        [np.pi / 2, 2.0]
    )


def test_progress_needs_a_full_step_below_the_best():
    assert made_progress(0.89, 1.0, 0.1)
    assert not made_progress(0.95, 1.0, 0.1)
    assert not made_progress(1.2, 1.0, 0.1)


def test_metrics_and_navigation_use_their_named_levers():
    assert metrics.HEADING_LEVER_M == REPORT_HEADING_LEVER_M
    assert metrics.PROGRESS_M == REPORT_PROGRESS_M
    assert DeadlockParams().heading_lever_m == NAV_HEADING_LEVER_M
    assert FieldParams().heading_lever_m == NAV_HEADING_LEVER_M
