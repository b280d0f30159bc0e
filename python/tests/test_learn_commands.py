"""The commands so101-learn's LeRobot recipes run (no process started): the demos recipe's launcher
and converter calls, lerobot-train with each preset, and the evaluation through so101-run-policy."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import pytest

from so101.learn import cli, dataset_facts, demos, lerobot_train
from so101.learn.checkpoints import record_items_in_memory


def parse(name: str, *argv: str) -> argparse.Namespace:
    """so101-learn's arguments for the recipe `name`, as its command line parses them."""
    return cli.parser().parse_args([name, *argv])


def test_demos_record_with_the_experts_noise_and_no_cameras_by_default(tmp_path):
    args = parse("demos", "--episodes", "7", "--waypoint-noise", "0.002", "--action-noise", "0.03")
    command = demos.launch_command(args, tmp_path)
    assert "--control=expert" in command and "--record" in command and "--episodes=7" in command
    assert "--teleop-args=--waypoint-noise 0.002 --action-noise 0.03" in command
    assert "--sim-args=--cameras none --servo-params sts3215 --randomize off" in command and "--speed=8" in command
    assert f"--bags={tmp_path / 'bags'}" in command


def test_demos_record_in_lockstep_or_at_a_speed(tmp_path):
    assert "--speed=lockstep" in demos.launch_command(parse("demos", "--speed", "lockstep"), tmp_path)
    assert "--speed=0.5" in demos.launch_command(parse("demos", "--speed", "0.5"), tmp_path)
    with pytest.raises(SystemExit):
        parse("demos", "--speed", "fast")


def test_demos_pass_the_servo_model_and_the_randomization_to_the_sim(tmp_path):
    fit, ranges = tmp_path / "fit.json", tmp_path / "mine.toml"
    fit.write_text("{}")
    ranges.write_text("")
    args = parse("demos", "--randomize", "--servo-params", str(fit))
    assert f"--sim-args=--cameras none --servo-params {fit} --randomize default" in demos.launch_command(args, tmp_path)
    args = parse("demos", "--randomize", str(ranges))
    assert any(part.endswith(f"--randomize {ranges}") for part in demos.launch_command(args, tmp_path))
    for spelling, spec in (("true", "default"), ("false", "off"), ("OFF", "off"), ("default", "default")):
        assert parse("demos", "--randomize", spelling).randomize == spec


def test_demos_refuse_a_randomization_or_servo_model_they_cannot_use(capsys):
    for argv in (["--randomize", "maybe"], ["--servo-params", "sts3250"]):
        with pytest.raises(SystemExit) as exit:
            parse("demos", *argv)
        assert exit.value.code == 2
        err = capsys.readouterr().err
        assert argv[1] in err and ("'default'" in err or "gain80" in err), err


def test_demos_with_cameras_slow_down_so_every_frame_is_rendered(tmp_path):
    args = parse("demos", "--cameras", "top:128x96")
    command = demos.launch_command(args, tmp_path)
    assert any(part.startswith("--sim-args=--cameras top:128x96 ") for part in command)
    assert "--speed=4" in command


def test_failed_demonstrations_stay_out_unless_kept(tmp_path):
    assert "--successful-only" in demos.convert_command(parse("demos"), tmp_path)
    assert "--successful-only" not in demos.convert_command(parse("demos", "--keep-failures"), tmp_path)


@pytest.mark.parametrize("recipe", ["act", "diffusion"])
def test_lerobot_train_gets_the_whole_preset_and_extra_arguments_last(recipe, tmp_path):
    dataset = tmp_path / "my_demos"
    args = parse(recipe, "--dataset", str(dataset), "--steps", "50", "--policy-arg=--policy.foo=1")
    command = lerobot_train.train_command(args, tmp_path / "out")
    # A dataset without cameras: lerobot-train, its items kept in memory.
    assert command[:3] == [sys.executable, "-m", "so101.learn.train_in_memory"]
    assert f"--policy.type={recipe}" in command and "--policy.device=cpu" in command
    for key, value in lerobot_train.PRESETS[recipe]["policy"].items():
        assert f"--policy.{key}={value}" in command
    for key, value in lerobot_train.PRESETS[recipe].get("training", {}).items():
        assert f"--{key}={value}" in command
    assert "--steps=50" in command and f"--dataset.root={dataset.resolve()}" in command
    assert "--save_freq=50" in command  # never beyond the last step, so `last` exists
    assert any(arg.startswith("--policy.normalization_mapping=") and '"ENV":"MEAN_STD"' in arg for arg in command)
    # draccus takes the last value of a repeated option: extra arguments override the preset.
    assert command[-1] == "--policy.foo=1"


def dataset_of_tasks(root: Path, *texts: str) -> Path:
    """A dataset's meta/tasks.parquet as LeRobot writes it (the task texts as the index)."""
    import pandas as pd

    (root / "meta").mkdir(parents=True)
    pd.DataFrame({"task_index": range(len(texts))}, index=pd.Index(texts, name="task")).to_parquet(
        root / "meta" / "tasks.parquet"
    )
    return root


def test_evaluation_goes_through_the_runner_on_unseen_seeds(tmp_path):
    dataset_of_tasks(tmp_path, "put the cube in the bin")
    args = parse("act", "--dataset", str(tmp_path), "--eval", "100")
    command = lerobot_train.eval_command(args, tmp_path / "model", tmp_path / "eval")
    assert "--sim-task=cube_to_bin" in command
    assert command[command.index("-m") + 1] == "so101.evaluate.run_policy"
    assert "--eval=100" in command and "--seed=1000" in command and "--backend=ros" in command
    assert "--videos=10" in command
    # Outside a network namespace (as here) the runner is put inside one.
    assert Path(command[0]).name == "isolated"


def test_the_recipe_evaluates_on_the_task_of_the_datasets_text(tmp_path):
    for texts, task in ((["lift the cube"], "lift_cube"), (["lift the cube", "put the cube in the bin"], "cube_to_bin")):
        root = dataset_of_tasks(tmp_path / str(len(texts)), *texts)
        args = parse("act", "--dataset", str(root), "--eval", "10")
        command = lerobot_train.eval_command(args, tmp_path / "model", tmp_path / "eval")
        assert f"--sim-task={task}" in command, command


def test_diffusion_scales_actions_into_its_samplers_clip_range_act_by_mean_and_std(tmp_path):
    import json

    for recipe, action in (("diffusion", "MIN_MAX"), ("act", "MEAN_STD")):
        command = lerobot_train.train_command(parse(recipe, "--dataset", str(tmp_path)), tmp_path / "out")
        (mapping,) = [arg.split("=", 1)[1] for arg in command if arg.startswith("--policy.normalization_mapping=")]
        assert json.loads(mapping)["ACTION"] == action, recipe


def write_info(dataset: Path, features: dict) -> None:
    import json

    (dataset / "meta").mkdir(parents=True)
    (dataset / "meta" / "info.json").write_text(json.dumps({"features": features}))


def test_a_dataset_with_cameras_gets_a_backbone_from_scratch_and_colour_augmentation_only(tmp_path):
    import json

    state = {"observation.state": {"dtype": "float32", "shape": [6]}, "action": {"dtype": "float32", "shape": [6]}}
    write_info(tmp_path / "state", state)
    write_info(tmp_path / "cameras", {**state, "observation.images.top": {"dtype": "video", "shape": [72, 96, 3]}})
    assert dataset_facts.dataset_cameras(tmp_path / "cameras") == ["observation.images.top"]

    def command(dataset: str, recipe: str = "act") -> list[str]:
        return lerobot_train.train_command(parse(recipe, "--dataset", str(tmp_path / dataset)), tmp_path / "o")

    assert not any("image_transforms" in arg or "backbone" in arg for arg in command("state"))
    assert "--steps=1500" in command("state") and "--batch_size=64" in command("state")
    vision = command("cameras")
    # A camera policy's own length: the annealing that brought the grasp ends at 4,000 steps.
    assert "--steps=4000" in vision and "--batch_size=32" in vision
    chosen = lerobot_train.train_command(parse("act", "--dataset", str(tmp_path / "cameras"), "--steps", "7"), tmp_path / "o")
    assert "--steps=7" in chosen and "--batch_size=32" in chosen
    assert "--policy.pretrained_backbone_weights=null" in vision
    assert "--dataset.image_transforms.enable=true" in vision
    (tfs,) = [arg.split("=", 1)[1] for arg in vision if arg.startswith("--dataset.image_transforms.tfs=")]
    transforms = json.loads(tfs)
    # LeRobot's own colour transforms, its geometric one left out (it would move the cube).
    assert {"brightness", "contrast", "saturation", "hue", "sharpness"} == set(transforms)
    assert transforms["brightness"]["type"] == "ColorJitter"
    diffusion = command("cameras", "diffusion")
    assert "--dataset.image_transforms.enable=true" in diffusion and "--policy.pretrained_backbone_weights=null" in diffusion


def test_several_processes_train_through_accelerates_launcher(tmp_path):
    args = parse("act", "--dataset", str(tmp_path), "--num-processes", "2", "--policy-arg=--policy.foo=1")
    command = lerobot_train.train_command(args, tmp_path / "out")
    assert Path(command[0]).name == "accelerate" and command[1] == "launch"
    assert "--num_processes=2" in command
    module = command.index("-m")
    assert command[module + 1] == "so101.learn.train_in_memory"
    # lerobot-train's own arguments follow unchanged, the extra ones last.
    assert "--policy.type=act" in command[module:] and command[-1] == "--policy.foo=1"
    # A rendezvous port of its own (two trainings never join one group), no forked loader on the CPU.
    ports = [int(arg.split("=")[1]) for arg in command if arg.startswith("--main_process_port=")]
    assert len(ports) == 1 and ports[0] > 0 and "--num_workers=0" in command
    assert lerobot_train.train_command(parse("act", "--dataset", str(tmp_path)), tmp_path)[1:3] == [
        "-m",
        "so101.learn.train_in_memory",
    ]
    cameras = camera_dataset(tmp_path / "cameras")
    command = lerobot_train.train_command(parse("act", "--dataset", str(cameras), "--num-processes", "2"), tmp_path / "out")
    assert command[command.index("-m") + 1] == "so101.learn.train_in_memory"
    reread = parse("act", "--dataset", str(cameras), "--num-processes", "2", "--reread-items")
    assert (command := lerobot_train.train_command(reread, tmp_path / "out"))[
        command.index("-m") + 1
    ] == "lerobot.scripts.lerobot_train"


def camera_dataset(root: Path) -> Path:
    """A dataset's meta/info.json with joints and one camera."""
    state = {"observation.state": {"dtype": "float32", "shape": [6]}, "action": {"dtype": "float32", "shape": [6]}}
    write_info(root, {**state, "observation.images.top": {"dtype": "video", "shape": [72, 96, 3]}})
    return root


def test_every_dataset_keeps_its_items_in_memory_unless_told(tmp_path):
    state = tmp_path / "state"
    write_info(state, {"observation.state": {"dtype": "float32", "shape": [6]}, "action": {"dtype": "float32", "shape": [6]}})
    kept = lerobot_train.train_command(parse("diffusion", "--dataset", str(state)), tmp_path / "o")
    # In memory: no loader process (it would keep copies of its own).
    assert kept[:3] == [sys.executable, "-m", "so101.learn.train_in_memory"] and "--num_workers=0" in kept
    reread = lerobot_train.train_command(parse("diffusion", "--dataset", str(state), "--reread-items"), tmp_path / "o")
    assert Path(reread[0]).name == "lerobot-train" and "--num_workers=1" in reread
    # The rest of the command is the same.
    assert [a for a in kept[3:] if not a.startswith("--num_workers")] == [
        a for a in reread[1:] if not a.startswith("--num_workers")
    ]
    # With cameras too, keeping the loader process that applies the augmentation beside the step.
    with_cameras = camera_dataset(tmp_path / "cameras")
    cameras = lerobot_train.train_command(parse("act", "--dataset", str(with_cameras)), tmp_path / "o")
    assert cameras[:3] == [sys.executable, "-m", "so101.learn.train_in_memory"] and "--num_workers=1" in cameras
    reread = lerobot_train.train_command(parse("act", "--dataset", str(with_cameras), "--reread-items"), tmp_path / "o")
    assert Path(reread[0]).name == "lerobot-train" and reread[1:] == cameras[3:]


def test_a_gpu_gets_more_loader_processes_than_the_cpu(tmp_path, monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 16)
    tmp_path = camera_dataset(tmp_path / "cameras")
    workers = {
        device: next(
            a
            for a in lerobot_train.train_command(parse("act", "--dataset", str(tmp_path), "--device", device), tmp_path)
            if a.startswith("--num_workers=")
        )
        for device in ("cpu", "cuda")
    }
    assert workers == {"cpu": "--num_workers=1", "cuda": "--num_workers=8"}
    two_gpus = parse("act", "--dataset", str(tmp_path), "--device", "cuda", "--num-processes", "2")
    assert "--num_workers=7" in lerobot_train.train_command(two_gpus, tmp_path)
    chosen = parse("act", "--dataset", str(tmp_path), "--device", "cuda", "--loader-workers", "3")
    assert "--num_workers=3" in lerobot_train.train_command(chosen, tmp_path)


def test_inprocess_demos_take_the_sims_camera_notation_with_sizes():
    from so101.learn.demos_inprocess import camera_sizes

    assert camera_sizes("none") == {}
    assert camera_sizes("top:96x72,wrist:64x48") == {"top": (72, 96), "wrist": (48, 64)}
    for wrong in ("top", "side:96x72", "top:24x18", "top:96by72"):
        with pytest.raises(ValueError):
            camera_sizes(wrong)


def test_demos_record_in_parallel_only_in_process(tmp_path):
    args = parse("demos", "--workers", "2", "--output", str(tmp_path))
    with pytest.raises(SystemExit, match="--backend inprocess"):
        demos.run(args)


def test_the_inprocess_summary_counts_a_regrasp_beside_the_success_it_led_to():
    from so101.learn.demos_inprocess import Recorded

    results = [
        Recorded(0, True, 300, True, "", None, regrasps=1),
        Recorded(1, True, 280, True, "", None),
        Recorded(2, False, 496, True, "", None, regrasps=2),  # a driven episode that regrasped and failed
        Recorded(3, False, 496, False, "", None),
    ]
    line = demos.inprocess_summary(results, 60.0, after=(144, Path("runs/pdemos/dataset")))
    assert "4 demonstration(s) played, 2 successful (1 of them after a regrasp; 2 regrasped in all)" in line
    assert "3 kept (1076 frames), in 60 s (4.0/min), after the 144 episode(s) of runs/pdemos/dataset" in line


def interrupted_run(
    tmp_path: Path,
    policy_type: str = "act",
    step: int = 200,
    processes: int = 1,
    cameras: bool = True,
    in_memory: bool = False,
    loader_workers: int | None = None,
) -> Path:
    """An output directory as lerobot-train leaves it after its checkpoint of `step` on a camera dataset (the
    checkpoints/last link, train_config.json and training_step.json; no weights, no process), with the record
    so101.learn.train_in_memory leaves in it if `in_memory`, and lerobot-train's num_workers if given."""
    output = tmp_path / "run"
    checkpoint = output / "checkpoints" / f"{step:06d}"
    (checkpoint / "pretrained_model").mkdir(parents=True)
    (checkpoint / "training_state").mkdir()
    (output / "checkpoints" / "last").symlink_to(checkpoint.name)
    if cameras:
        camera_dataset(tmp_path / "data")
    config = {
        "policy": {"type": policy_type, "device": "cpu"},
        "dataset": {"root": str(tmp_path / "data")},
        "steps": 4000,
        "batch_size": 32,
    }
    if loader_workers is not None:
        config["num_workers"] = loader_workers
    (checkpoint / "pretrained_model" / "train_config.json").write_text(json.dumps(config))
    state = {"step": step, "num_processes": processes, "batch_size": 32}
    (checkpoint / "training_state" / "training_step.json").write_text(json.dumps(state))
    if in_memory:
        record_items_in_memory(checkpoint, 1000)
    return output


def test_a_resumed_run_continues_its_checkpoint_with_its_own_settings(tmp_path):
    output = interrupted_run(tmp_path)
    args = parse("act", "--resume", str(output), "--policy-arg=--log_freq=10")
    run_dir, last = lerobot_train.resume_settings(args)
    assert run_dir == output.resolve() and last.step == 200
    # The dataset, length and device the evaluation and summary use are the run's.
    assert (args.dataset, args.steps, args.batch_size, args.device) == (str(tmp_path / "data"), 4000, 32, "cpu")
    command = lerobot_train.resume_command(args, last, run_dir)
    assert Path(command[0]).name == "lerobot-train"
    assert command[1:] == [
        f"--config_path={run_dir / 'checkpoints' / 'last' / 'pretrained_model' / 'train_config.json'}",
        "--resume=true",
        f"--output_dir={run_dir}",
        "--steps=4000",
        "--policy.device=cpu",
        "--num_workers=1",  # the CPU's loader, as for a new run
        "--log_freq=10",
    ]
    longer = parse("act", "--resume", str(output), "--steps", "5000", "--save-every", "100", "--loader-workers", "0")
    command = lerobot_train.resume_command(longer, lerobot_train.resume_settings(longer)[1], run_dir)
    assert longer.steps == 5000 and {"--steps=5000", "--save_freq=100", "--num_workers=0"} <= set(command)


def test_a_resumed_run_on_a_dataset_without_cameras_keeps_its_items_in_memory(tmp_path):
    output = interrupted_run(tmp_path, policy_type="diffusion", cameras=False, in_memory=True)
    args = parse("diffusion", "--resume", str(output))
    command = lerobot_train.resume_command(args, lerobot_train.resume_settings(args)[1], output.resolve())
    assert command[:3] == [sys.executable, "-m", "so101.learn.train_in_memory"] and "--num_workers=0" in command


def test_a_resumed_run_of_lerobot_trains_own_loading_keeps_it(tmp_path):
    """A run that read its items at every step (--reread-items, or started before the items were
    kept) resumes that way, with its loader process: other loading would give other weights."""
    output = interrupted_run(tmp_path, policy_type="diffusion", cameras=False)
    args = parse("diffusion", "--resume", str(output))
    command = lerobot_train.resume_command(args, lerobot_train.resume_settings(args)[1], output.resolve())
    assert Path(command[0]).name == "lerobot-train" and "--num_workers=1" in command
    # A checkpoint copied without its run directory keeps the record: it is the checkpoint's.
    kept = interrupted_run(tmp_path / "kept", policy_type="diffusion", cameras=False, in_memory=True)
    assert lerobot_train.resume_settings(parse("diffusion", "--resume", str(kept)))[1].items_in_memory
    with pytest.raises(SystemExit, match="own dataset, output, batch size, seed and loading: leave out --reread-items"):
        lerobot_train.resume_settings(parse("diffusion", "--resume", str(output), "--reread-items"))


def test_a_resumed_run_keeps_its_loader_processes_where_it_stays(tmp_path):
    """A run started with --loader-workers 0 resumes with none (a loader process changes the
    weights); moved to a GPU it gets the GPU's loaders, and --loader-workers overrides either."""
    output = interrupted_run(tmp_path, loader_workers=0)
    args = parse("act", "--resume", str(output))
    assert "--num_workers=0" in lerobot_train.resume_command(args, lerobot_train.resume_settings(args)[1], output.resolve())
    moved = parse("act", "--resume", str(output), "--device", "cuda")
    command = lerobot_train.resume_command(moved, lerobot_train.resume_settings(moved)[1], output.resolve())
    assert "--num_workers=0" not in command
    told = parse("act", "--resume", str(output), "--loader-workers", "2")
    assert "--num_workers=2" in lerobot_train.resume_command(told, lerobot_train.resume_settings(told)[1], output.resolve())


def test_a_resumed_run_keeps_its_processes_and_may_be_a_copy_without_links(tmp_path):
    output = interrupted_run(tmp_path, processes=2)
    last = output / "checkpoints" / "last"
    target = last.resolve()
    last.unlink()
    shutil.copytree(target, last)  # what scp -r or a zip makes of the link
    args = parse("act", "--resume", str(output))
    run_dir, checkpoint = lerobot_train.resume_settings(args)
    assert checkpoint.step == 200 and args.num_processes == 2
    command = lerobot_train.resume_command(args, checkpoint, run_dir)
    # Two processes again, through accelerate, with no loader forked beside the gloo group.
    assert Path(command[0]).name == "accelerate" and "--num_processes=2" in command and "--num_workers=0" in command


def test_resume_refuses_what_it_cannot_continue(tmp_path):
    output = interrupted_run(tmp_path)
    with pytest.raises(SystemExit, match="leave out --dataset, --seed"):
        lerobot_train.resume_settings(parse("act", "--resume", str(output), "--dataset", str(tmp_path), "--seed", "3"))
    with pytest.raises(SystemExit, match="resume it with so101-learn act"):
        lerobot_train.resume_settings(parse("diffusion", "--resume", str(output)))
    with pytest.raises(SystemExit, match="no checkpoint to resume from"):
        lerobot_train.resume_settings(parse("act", "--resume", str(tmp_path / "started-just-now")))
    with pytest.raises(SystemExit, match="has trained 200 steps of 200 already: --steps N"):
        lerobot_train.resume_settings(parse("act", "--resume", str(output), "--steps", "200"))
    (output / "checkpoints" / "last").unlink()
    with pytest.raises(SystemExit, match=r"beside the checkpoints 000200: point it at the newest whole one \(ln -sfn 000200"):
        lerobot_train.resume_settings(parse("act", "--resume", str(output)))
    with pytest.raises(SystemExit, match="--dataset is required"):
        lerobot_train.run(parse("act"))


def test_demos_push_the_arm_in_process_only_and_by_a_finite_amount(tmp_path):
    for extra, message in (([], "in-process only"), (["--backend", "inprocess", "--perturb", "nan"], "finite")):
        perturb = [] if "--perturb" in extra else ["--perturb", "0.05"]
        args = parse("demos", *perturb, *extra, "--output", str(tmp_path))
        with pytest.raises(SystemExit, match=message):
            demos.run(args)


def test_bf16_is_lerobots_mixed_precision_kept_on_resume_and_warned_of_where_emulated(tmp_path):
    dataset = tmp_path / "my_demos"
    plain = lerobot_train.train_command(parse("act", "--dataset", str(dataset)), tmp_path / "a")
    assert not any("use_amp" in arg for arg in plain)
    args = parse("act", "--dataset", str(dataset), "--bf16", "--policy-arg=--policy.foo=1")
    command = lerobot_train.train_command(args, tmp_path / "b")
    assert "--policy.use_amp=true" in command and command[-1] == "--policy.foo=1"
    # Resumed, the run's config keeps use_amp; --bf16 given again says so once more, never the opposite.
    assert "--policy.use_amp=true" in lerobot_train.precision_settings(parse("act", "--resume", "x", "--bf16"))
    assert lerobot_train.precision_settings(argparse.Namespace()) == []  # a VLA's recipe sets its dtype itself
    amx = "fpu avx512f avx512_bf16 amx_bf16 amx_tile"
    avx2 = "fpu sse2 avx avx2 fma"
    assert lerobot_train.cpu_bf16_problem("cpu", amx) is None
    assert "no AMX" in lerobot_train.cpu_bf16_problem("cpu", "avx512f avx512_bf16")
    assert "emulated" in lerobot_train.cpu_bf16_problem("cpu", avx2)
    assert lerobot_train.cpu_bf16_problem("cuda", avx2) is None
    flags = lerobot_train.cpu_flags()
    assert isinstance(flags, str) and (not Path("/proc/cpuinfo").exists() or "fpu" in flags.split())
