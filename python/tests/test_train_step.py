"""so101-bench train_step reads LeRobot's own log of a training's windows of steps."""

import pytest

from so101.bench.train_step import VARIANTS, profile, windows


def lerobot_log_line(update_s: float, data_s: float) -> str:
    """One window's line as lerobot-train logs it: LeRobot's MetricsTracker and AverageMeter with
    the meters lerobot-train registers (loss, grdn, lr, updt_s, data_s, smp/s)."""
    from lerobot.utils.logging_utils import AverageMeter, MetricsTracker

    meters = {
        "loss": AverageMeter("loss", ":.3f"),
        "grad_norm": AverageMeter("grdn", ":.3f"),
        "lr": AverageMeter("lr", ":0.1e"),
        "update_s": AverageMeter("updt_s", ":.3f"),
        "dataloading_s": AverageMeter("data_s", ":.3f"),
        "samples_per_s": AverageMeter("smp/s", ":.0f"),
    }
    tracker = MetricsTracker(32, 25777, 100, meters)
    tracker.loss, tracker.grad_norm, tracker.lr = 0.9, 12.0, 1e-4
    tracker.update_s, tracker.dataloading_s, tracker.samples_per_s = update_s, data_s, 32 / (update_s + data_s)
    tracker.step()
    return f"INFO 2026-11-28 02:40:00 ot_train.py:640 {tracker}"


def test_the_first_window_is_left_out_and_the_rest_averaged():
    log = "\n".join(
        ["Training: 10%|#  | 4/40 [00:20<02:00, 3.1s/step]"]
        + [lerobot_log_line(u, d) for u, d in [(9.0, 4.0), (2.0, 0.5), (3.0, 0.25)]]
    )
    assert windows(log) == [(9.0, 4.0), (2.0, 0.5), (3.0, 0.25)]
    measured = profile(log)
    assert measured["windows"] == 2
    assert measured["update_s"] == pytest.approx(2.5) and measured["data_s"] == pytest.approx(0.375)
    assert measured["step_s"] == pytest.approx(2.875)
    # --skip leaves out more windows (a first pass through a dataset kept in memory).
    assert profile(log, skip=2)["update_s"] == pytest.approx(3.0)


def test_a_run_too_short_to_measure_says_so():
    with pytest.raises(ValueError, match="--steps"):
        profile(lerobot_log_line(1.0, 0.1))


def test_every_variant_changes_the_recipe_through_its_own_options():
    from so101.learn.cli import parser

    recipe = vars(parser().parse_args(["act", "--dataset", "d"]))
    for name, extra in VARIANTS.items():
        varied = vars(parser().parse_args(["act", "--dataset", "d", *extra]))
        assert (varied != recipe) == bool(extra), name
