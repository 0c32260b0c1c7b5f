"""Smoke test of the Section 5.2 experiment: a tiny run writes every acceptance figure."""

from __future__ import annotations

import json

import pytest

from sumo_scenarios.experiment import (
    DrivingExperimentConfig,
    evaluate_saved_policy,
    format_summary,
    plot_results,
    run_experiment,
)


def test_tiny_run_writes_every_acceptance_figure_and_the_plots(tmp_path):
    cfg = DrivingExperimentConfig(
        seeds=(0,),
        eval_steps=100,
        accuracy_window=20,
        max_noninteractive=60,
        confident_demos=20,
        stage_every=10,
        burst=5,
        arm_b_stages=(60, 80),
        max_new=10,
        max_components=3,
        train_episode_steps=100,
        extra_eval_segments=(1,),
    )
    res = run_experiment(cfg, tmp_path, workers=1, progress=False)
    on_disk = json.loads((tmp_path / "results.json").read_text())
    assert on_disk["acceptance"] == res["acceptance"]
    assert set(on_disk["acceptance"]) == {
        "straight_in_28_32",
        "expert_le_0.5",
        "arm_a_demos_le_650",
        "arm_a_le_2pct",
        "arm_a_tv_le_0.15",
        "arm_a_beats_arm_b",
    }
    s = on_disk["summary"]
    assert list(s) == [
        "straight",
        "a_end_noninteractive",
        "a_plus10",
        "a_plus20",
        "b_60",
        "b_80",
        "expert",
    ]
    for label, entry in s.items():
        assert 0.0 <= entry["collision_pct"]["mean"] <= 100.0, label
        assert sum(entry["lanes"]) == pytest.approx(1.0)
        assert 0.0 <= entry["tv_to_expert"]["mean"] <= 1.0
    assert s["straight"]["lanes"][2] == 1.0 and s["expert"]["tv_to_expert"]["mean"] == 0.0
    for entry in s.values():  # the secondary average over the extra held-out segments
        assert 0.0 <= entry["all_segments"]["collision_pct"]["mean"] <= 100.0
        assert sum(entry["all_segments"]["lanes"]) == pytest.approx(1.0)
    n_ni = on_disk["per_seed"][0]["noninteractive_demos"]
    assert s["a_plus20"]["demonstrations"]["mean"] == n_ni + 20
    for entry in on_disk["per_seed"][0]["stages"].values():  # snapshots hold every demo
        if "demonstrations" in entry:
            assert entry["fitted_on"] == entry["demonstrations"]
    assert s["b_80"]["demonstrations"]["mean"] == 80
    assert s["a_plus20"]["components_total"]["mean"] >= 3
    for name in (
        "fig8_lanes_collisions.png",
        "fig6_accuracy.png",
        "fig9_accuracy.png",
        "fig10_confidence.png",
        "seed_0/episodes.json",
    ):
        assert (tmp_path / name).stat().st_size > 1000, name
    assert on_disk["domain"] == "driving"
    # the figures can be redrawn from results.json alone
    (tmp_path / "fig8_lanes_collisions.png").unlink()
    written = plot_results(on_disk, tmp_path)
    assert tmp_path / "fig8_lanes_collisions.png" in written
    assert all(p.stat().st_size > 1000 for p in written)
    text = format_summary(on_disk)
    assert "arm a final, collisions %" in text and "2 segments" in text
    with pytest.raises(ValueError, match="distinct"):
        DrivingExperimentConfig(eval_segment=1, extra_eval_segments=(1,))


def test_a_saved_teaching_session_is_evaluated_on_the_held_out_road(tmp_path):
    from sumo_scenarios.env import DrivingEnv
    from sumo_scenarios.expert import ScriptedExpert
    from torchcbl import ConfidentTeacher, TeachingConfig

    env = DrivingEnv(scenario="train", max_episode_steps=200)
    try:
        ct = ConfidentTeacher(
            env,
            ScriptedExpert(seed=0),
            config=TeachingConfig(accuracy_window=50, target_accuracy=None, max_new=20),
            run_dir=tmp_path / "session",
            progress=False,
        )
        ct.run(max_demonstrations=120)
        ct.close()
    finally:
        env.close()
    report = evaluate_saved_policy(tmp_path / "session", n_steps=150, seed=0)
    assert report["steps"] == 150 and report["eval_segment"] == 0
    assert sum(report["lanes"]) == pytest.approx(1.0)
    # the expert's habits were learned: it keeps off the right lane and right shoulder
    assert report["lanes"][0] + report["lanes"][1] < 0.2
    assert 0.0 <= report["collision_pct"] < 10.0
