"""`posecons study` at toy size: runs → result JSONs → report, skipping finished runs, resuming an
interrupted one, rebuilding the report from copied JSONs; the pairing of variants by seed; specs."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest
import torch
import yaml
from filelock import FileLock

from posecons.checkpoint import load_checkpoint
from posecons.cli import main
from posecons.config import STUDY_SPECS, load_config, preset_names, resolve_preset
from posecons.errors import PoseconsError
from posecons.study import report, runner
from posecons.study.spec import load_spec
from posecons.training.initial_weights import save_initial_weights
from posecons.training.precision import cpu_kind, processor_name
from posecons.training.trainer import Trainer

SYNTH = {"drives": 3, "frames": 16, "width": 128, "height": 64, "neighbours": 3, "seed": 0}
TINY = ["model.width=128", "train.max_steps=3", "train.batch_size=2", "train.val_every=off"]
EXPERIMENTS = Path(__file__).resolve().parents[1] / "experiments" / "specs"  # the investigation's specs, run as files


def write_spec(path: Path, **changes) -> Path:
    spec = {
        "preset": "synth/demo",
        "overrides": TINY,
        "data": {"synth": SYNTH},
        "seeds": [0],
        "variants": {"baseline": ["loss.constraints=[]"], "cyc": ["loss.constraints=[cyc]"]},
        **changes,
    }
    path.write_text(yaml.safe_dump(spec))
    return path


def table_rows(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("|")]


@pytest.mark.slow
def test_study_end_to_end_skips_done_runs_resumes_interrupted_and_rebuilds_from_json(tmp_path, monkeypatch, capsys):
    # The cyc run keeps an EMA of its weights: its result pairs them with its raw weights.
    variants = {"baseline": ["loss.constraints=[]"], "cyc": ["loss.constraints=[cyc]", "train.ema_decay=0.5"]}
    spec, out = write_spec(tmp_path / "toy.yaml", variants=variants), tmp_path / "study"
    argv = ["study", "--spec", str(spec), "--out", str(out), "--quiet", "--accelerator", "cpu"]
    calls = []
    real_train = runner.train

    def spy(config, data, run_dir, **kwargs):
        calls.append((Path(run_dir).parent.name, kwargs["resume"]))
        return real_train(config, data, run_dir, **kwargs)

    monkeypatch.setattr(runner, "train", spy)

    def stop_cyc_after_one_step(self):  # as if Ctrl-C arrived during the cyc run's first step
        if "cyc" in str(self.out) and self.step == 1:
            self.stop.signum = signal.SIGINT
        return bool(self.stop.signum)

    with monkeypatch.context() as m:
        m.setattr(Trainer, "_stop_requested", stop_cyc_after_one_step)
        assert main(argv) == 130
    assert "run the same `posecons study` command again" in capsys.readouterr().err
    results = out / "results"
    assert (results / "baseline_seed0.json").is_file() and not (results / "cyc_seed0.json").exists()
    assert load_checkpoint(out / "runs/cyc/seed0/checkpoints/last.pt")["step"] == 1
    assert "missing: cyc seed 0" in (out / "results.md").read_text()  # the partial report says so

    assert main(argv) == 0  # resumes cyc from step 1, leaves baseline alone
    assert calls == [("baseline", False), ("cyc", False), ("cyc", True)]
    cyc = json.loads((results / "cyc_seed0.json").read_text())
    assert cyc["steps"] == 3 and cyc["checkpoint"]["step"] == 3 and cyc["checkpoint"]["file"].endswith("last.pt")
    assert cyc["overrides"][-3:] == [*variants["cyc"], "train.seed=0"] and cyc["config"]["train"]["seed"] == 0
    for scaling in ("frame", "sequence"):
        depth = cyc["depth"][scaling]
        assert depth["scaling"] == scaling and len(depth["scales"]) == len(cyc["test_lines"]) == SYNTH["frames"]
    assert set(cyc["pose"]) == {"02"} and "const_velocity" in cyc["pose"]["02"]
    raw = cyc["raw_weights"]  # evaluated the same way, but not the EMA again
    assert raw["depth"]["frame"]["abs_rel"] != cyc["depth"]["frame"]["abs_rel"] and set(raw["pose"]) == {"02"}
    assert raw["pose"]["02"]["ate_full_rmse"] != cyc["pose"]["02"]["ate_full_rmse"]
    assert raw["depth"]["sequence"]["predictions"].endswith("last.pt: raw_model")
    assert "raw_weights" not in json.loads((results / "baseline_seed0.json").read_text())
    untrained = json.loads((results / "untrained_seed0.json").read_text())
    assert untrained["checkpoint"]["step"] == 0 and untrained["depth"]["frame"]["abs_rel"] > 0
    floor = json.loads((results / "renderer_depth_seed0.json").read_text())["depth"]["frame"]
    assert floor["abs_rel"] < untrained["depth"]["frame"]["abs_rel"] / 2  # the renderer's depth: near perfect
    constant = json.loads((results / "constant_depth_seed0.json").read_text())["depth"]["frame"]
    assert constant["scale_cv"] == 0 or constant["abs_rel"] > floor["abs_rel"]  # one depth everywhere: no shape
    assert constant["predictions"] == "a constant depth" and len(constant["scales"]) == SYNTH["frames"]

    report = (out / "results.md").read_text()
    assert "runs done: 2 of 2" in report and "missing" not in report
    bar = 0.8 * constant["abs_rel"]
    learnt = {
        v: json.loads((results / f"{v}_seed0.json").read_text())["depth"]["frame"]["abs_rel"] <= bar for v in variants
    }
    assert f"A run has learnt when its abs rel is at most {bar:.3f}" in report
    for v, ok in learnt.items():
        assert f"| {v} | {int(ok)} of 1 |" in report
    assert report.index("## Runs that learnt") < report.index("## Depth")
    for part in ("Frame-median scaling", "Per-sequence scaling", "Odometry sequence 02", "Paired differences"):
        assert part in report
    assert (
        "| untrained | 1 |" in report
        and "| renderer_depth | 1 |" in report
        and "| baseline | 1 |" in report
        and "| cyc | 1 |" in report
    )
    assert "| **mean σ/μ** (primary) | cyc | 1 |" in report and "untestable (n < 6)" in report
    for plot in ("scale_boxplot.png", "scale_over_time.png", "paired_differences.png"):
        assert (results / plot).stat().st_size > 1000 and f"results/{plot}" in report

    docs = tmp_path / "docs" / "results.md"
    assert main(argv + ["--report", str(docs)]) == 0  # everything done: trains nothing, writes the report
    assert len(calls) == 3
    copies = sorted(p.name for p in (tmp_path / "docs/results/json").glob("[!.]*.json"))
    assert copies == [
        "baseline_seed0.json",
        "constant_depth_seed0.json",
        "cyc_seed0.json",
        "renderer_depth_seed0.json",
        "study.json",
        "untrained_seed0.json",
    ]
    again = tmp_path / "elsewhere" / "r.md"
    assert (
        main(["study", "--report-only", "--results", str(tmp_path / "docs/results/json"), "--report", str(again)]) == 0
    )
    assert table_rows(again.read_text()) == table_rows(docs.read_text()) == table_rows(report)
    assert (tmp_path / "elsewhere/r/scale_boxplot.png").is_file()

    write_spec(spec, overrides=[*TINY[:-3], "train.max_steps=4", *TINY[-2:]], variants=variants)
    assert main(argv) == 2  # a changed recipe does not mix with the runs already done
    assert "train.max_steps: 3 → 4" in capsys.readouterr().err
    assert len(calls) == 3


@pytest.mark.slow
def test_two_study_processes_share_a_folder_without_redoing_or_clashing(tmp_path, monkeypatch, capsys):
    variants = {v: [f"loss.constraints=[{c}]"] for v, c in (("baseline", ""), ("cyc", "cyc"), ("id", "id"))}
    spec, out = write_spec(tmp_path / "toy.yaml", variants=variants), tmp_path / "study"
    argv = ["study", "--spec", str(spec), "--out", str(out), "--quiet", "--accelerator", "cpu"]
    calls, results = [], out / "results"
    real_train, real_in_progress = runner.train, runner.run_in_progress
    monkeypatch.setattr(
        runner,
        "train",
        lambda c, d, run_dir, **kw: calls.append(run_dir.parent.name) or real_train(c, d, run_dir, **kw),
    )

    def meanwhile(run_dir):  # while this process looks at cyc, another one finishes id
        if run_dir.parent.name == "cyc":
            result = json.loads((results / "baseline_seed0.json").read_text())
            result["variant"], result["config"]["loss"]["constraints"] = "id", ["id"]
            (results / "id_seed0.json").write_text(json.dumps(result))
        return real_in_progress(run_dir)

    monkeypatch.setattr(runner, "run_in_progress", meanwhile)
    cyc = out / "runs" / "cyc" / "seed0"
    cyc.mkdir(parents=True)
    with FileLock(cyc / ".lock", timeout=0):  # another process is training cyc
        assert main(argv) == 0
    printed = capsys.readouterr().out
    assert calls == ["baseline"]
    assert (
        "skip cyc seed 0: another process is training it" in printed
        and "skip id seed 0: finished by another" in printed
    )
    assert "1 runs trained or resumed now" in printed
    assert [p.name for p in cyc.iterdir()] == [".lock"] and not (results / "cyc_seed0.json").exists()
    assert "missing: cyc seed 0" in (out / "results.md").read_text()

    monkeypatch.setattr(runner, "run_in_progress", real_in_progress)
    assert main(argv) == 0  # that process gone: this one trains cyc, and only cyc
    assert calls == ["baseline", "cyc"] and "runs done: 3 of 3" in (out / "results.md").read_text()


def test_a_failing_run_is_recorded_and_the_others_go_on(tmp_path, monkeypatch, capsys):
    """A run fails, the next one trains: the failure is recorded (error line, traceback log), listed in
    the report, the rest trains, exit status 1; the same command retries only it and clears the record.
    Mutations: stopping at the first failure (baseline untrained); no record; a record kept after success."""
    variants = {v: [f"loss.constraints=[{c}]"] for v, c in (("baseline", ""), ("broken", "cyc"), ("id", "id"))}
    spec, out = write_spec(tmp_path / "toy.yaml", variants=variants), tmp_path / "study"
    argv = ["study", "--spec", str(spec), "--out", str(out), "--quiet", "--accelerator", "cpu"]
    real_train, calls = runner.train, []

    def flaky(config, data, run_dir, **kwargs):
        calls.append(run_dir.parent.name)
        if run_dir.parent.name == "broken" and calls.count("broken") == 1:
            raise RuntimeError("boom in the loader")
        return real_train(config, data, run_dir, **kwargs)

    monkeypatch.setattr(runner, "train", flaky)
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "1 of 3 runs failed" in err and "broken seed 0: RuntimeError: boom in the loader" in err
    record = json.loads((out / "results" / "failed" / "broken_seed0.json").read_text())
    assert record["error"] == "RuntimeError: boom in the loader"
    assert "Traceback" in Path(record["log"]).read_text() and (out / "results" / "id_seed0.json").is_file()
    assert "**failed** (the same command retries it): broken seed 0: RuntimeError" in (out / "results.md").read_text()

    assert main(argv) == 0 and calls == ["baseline", "broken", "id", "broken"]
    assert not (out / "results" / "failed" / "broken_seed0.json").exists()
    assert "failed" not in (out / "results.md").read_text().split("## ")[0]


@pytest.mark.slow
def test_a_failing_worker_does_not_stop_the_other_lanes(tmp_path, capsys):
    """--jobs 2 with a run that fails at once: the third run still starts (it used to stop scheduling)."""
    variants = {
        "broken": ["train.batch_size=64"],
        "baseline": ["loss.constraints=[]"],
        "cyc": ["loss.constraints=[cyc]"],
    }
    spec, out = write_spec(tmp_path / "toy.yaml", variants=variants), tmp_path / "study"
    argv = ["study", "--spec", str(spec), "--out", str(out), "--quiet", "--accelerator", "cpu", "--jobs", "2"]
    assert main(argv) == 1
    assert all((out / "results" / f"{v}_seed0.json").is_file() for v in ("baseline", "cyc"))
    record = json.loads((out / "results" / "failed" / "broken_seed0.json").read_text())
    assert (
        record["error"].startswith("exit status 2: posecons study (broken seed 0): error: ")
        and "fewer than one batch" in record["error"]
    )
    assert record["log"].endswith("study.log") and "FAILED broken seed 0" in capsys.readouterr().out


def test_a_spec_pins_the_compute_threads_of_its_runs_and_records_them(tmp_path, monkeypatch):
    """threads: 1 in a two-thread process: the run computes on one thread, its result says so, and
    the process gets its threads back. Caught: the key ignored in-process; not restored."""
    seen, real_train, before = [], runner.train, torch.get_num_threads()
    monkeypatch.setattr(runner, "train", lambda *a, **k: seen.append(torch.get_num_threads()) or real_train(*a, **k))
    spec = write_spec(tmp_path / "toy.yaml", variants={"baseline": ["loss.constraints=[]"]}, threads=1)
    out = tmp_path / "study"
    torch.set_num_threads(2)
    try:
        assert main(["study", "--spec", str(spec), "--out", str(out), "--quiet", "--accelerator", "cpu"]) == 0
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    result = json.loads((out / "results" / "baseline_seed0.json").read_text())
    assert seen == [1] and result["environment"]["threads"] == 1 and result["environment"]["cpu"] == cpu_kind()
    assert result["environment"]["processor"] == processor_name() != "unknown"
    assert "compute threads per run: 1, pinned by the spec" in (out / "results.md").read_text()
    with pytest.raises(PoseconsError, match="threads must be an integer ≥ 1"):
        load_spec(write_spec(tmp_path / "bad.yaml", threads=0))


def test_the_first_row_counts_the_runs_that_learnt_against_a_constant_depth():
    def result(variant, seed, abs_rel):
        return {"variant": variant, "seed": seed, "depth": {"frame": {"abs_rel": abs_rel}}}

    results = [result("constant_depth", 0, 0.5), result("a", 0, 0.399), result("a", 1, 0.4), result("a", 2, 0.401)]
    results += [result("b", 1, 1.2), result("b", 0, float("nan"))]
    table = report.learning_table(["a", "b"], results)
    assert "at most 0.400: 20% below a constant depth's (0.500" in table
    assert "| a | 2 of 3 | 2 (0.401) |" in table  # at the bar learns; above it does not
    assert "| b | 0 of 2 | 0 (nan), 1 (1.200) |" in table  # a NaN score has not learnt
    assert "not judged" in report.learning_table(["a"], results[1:])


def test_a_report_holds_only_the_runs_of_its_spec_seeds_and_variants(tmp_path):
    """The committed results folder holds five seeds of baseline and cyc and other specs' variants;
    a report of two seeds and one variant averages and pairs those alone. Its JSONs predate t_err /
    r_err and fill those columns from rpe_trans / rpe_rot (catches LEGACY_POSE_KEYS dropped or its
    factor of 100 for °/m → °/100 m lost)."""
    report = tmp_path / "r.md"
    argv = ["study", "--report-only", "--spec", "study/synth", "--variants", "cyc", "--seeds", "0", "1"]
    assert (
        main([*argv, "--results", str(Path(__file__).parents[1] / "docs/results/study/json"), "--report", str(report)])
        == 0
    )
    text = report.read_text()
    assert "| untrained | 2 |" in text and "| baseline | 2 |" in text and "| cyc | 2 |" in text
    assert "| **mean σ/μ** (primary) | cyc | 2 |" in text and "| renderer_depth | 1 |" in text
    assert "cyc_temporal" not in text and "| id |" not in text
    assert "| t_err (%) | r_err (°/100 m) |" in text and "| 163.95 ± 48.79 | 4.98 ± 0.41 |" in text  # untrained, 06


def test_a_report_of_results_with_the_removed_stabilisers_depth_leaves_it_out(tmp_path):
    """The committed 7-Scenes results hold "frame_stabilised" depth (from the removed `stabilise:` key):
    their report still builds, from the plain depth alone."""
    folder = Path(__file__).parents[1] / "docs/results/study_7scenes/json"
    assert "frame_stabilised" in json.loads((folder / "cyc_seed0.json").read_text())["depth"]
    report = tmp_path / "r.md"
    assert main(["study", "--report-only", "--results", str(folder), "--report", str(report)]) == 0
    text = report.read_text()
    assert "| **mean σ/μ** (primary) | cyc | 6 |" in text and "stabilis" not in text


def test_runs_are_paired_only_with_a_reference_run_that_computed_alike():
    """A seed's runs on another CPU kind, thread count or GPU than the reference's run of that seed
    are left out of the pairs and named; results that predate the records pair only with each other.
    Caught: the CPU kind, the threads read from the machine line or the GPU ignored."""

    def result(variant, seed, cv, machine="Linux x86_64, 2 CPU threads, 1 used", **env):
        depth = {"scale_cv": cv, "abs_rel": 0.2, "a1": 0.7}
        environment = {"machine": machine, **env}
        return {
            "variant": variant,
            "seed": seed,
            "depth": {"frame": depth, "sequence": depth},
            "environment": environment,
        }

    results = [result("baseline", s, 0.08, cpu="AVX512") for s in range(7)]
    results += [result("fb", s, 0.07, cpu="AVX2" if s == 4 else "AVX512") for s in range(7)]
    results += [result("baseline", 7, 0.08, machine="Linux x86_64, 2 CPU threads")]  # before threads were kept
    results += [result("fb", 7, 0.07, cpu="AVX512")]
    results += [
        result("baseline", s, 0.08, machine="Linux x86_64, 16 CPU threads, 8 used, NVIDIA H200") for s in (8, 9)
    ]
    results += [result("fb", 8, 0.07, machine="Linux x86_64, 16 CPU threads, 8 used, NVIDIA A100")]
    results += [result("fb", 9, 0.07, machine="Linux x86_64, 16 CPU threads, 8 used, NVIDIA H200")]
    results += [
        result("baseline", 10, 0.08, cpu="AVX2"),
        result("fb", 10, 0.07, "Linux x86_64, 2 CPU threads, 2 used", cpu="AVX2"),
    ]
    # one CPU kind, two processors: seed 11 on the same one, seed 12 not, seed 13's reference unrecorded
    results += [result(v, 11, cv, cpu="AVX512", processor="AMD EPYC") for v, cv in (("baseline", 0.08), ("fb", 0.07))]
    results += [result("baseline", 12, 0.08, cpu="AVX512", processor="AMD EPYC")]
    results += [result("fb", 12, 0.07, cpu="AVX512", processor="Intel Xeon")]
    results += [result("baseline", 13, 0.08, cpu="AVX512"), result("fb", 13, 0.07, cpu="AVX512", processor="AMD EPYC")]
    primary = next(r for r in report.paired_rows(["baseline", "fb"], results) if r["primary"])
    assert primary["n"] == 8 and primary["mean"] == pytest.approx(-0.01)  # seeds 0–3, 5, 6, 9 and 11
    left_out = "; ".join(report.pair_alike(["baseline", "fb"], results)[1])
    assert "fb seed 4 (1 thread(s), CPU AVX2; baseline: 1 thread(s), CPU AVX512)" in left_out
    assert "fb seed 7 (1 thread(s), CPU AVX512; baseline: unrecorded thread(s), CPU unrecorded)" in left_out
    assert (
        "fb seed 8 (8 thread(s), CPU unrecorded, NVIDIA A100; baseline: 8 thread(s), CPU unrecorded, NVIDIA H200)"
        in left_out
    )
    assert "fb seed 10 (2 thread(s), CPU AVX2; baseline: 1 thread(s), CPU AVX2)" in left_out
    assert "fb seed 12 (1 thread(s), CPU AVX512 (Intel Xeon); baseline: 1 thread(s), CPU AVX512 (AMD EPYC))" in left_out
    assert "fb seed 13 (1 thread(s), CPU AVX512 (AMD EPYC); baseline: 1 thread(s), CPU AVX512)" in left_out


def test_variants_of_a_seed_share_initial_weights_and_data_order(make_synth, tmp_path):
    """Seed k gives every variant the same initial weights (= the study's untrained network) and the
    same first batch; another seed changes both, so the comparison can fail."""
    data = make_synth(SYNTH["drives"], SYNTH["frames"], SYNTH["width"], SYNTH["height"], 0, "--neighbours", "3")
    preset = resolve_preset("synth/demo")
    variants = {
        "baseline": ["loss.constraints=[]", "train.seed=3"],
        "all": ["loss.constraints=[fb,id,cyc]", "loss.identity_fraction=0.5", "loss.cyc_weight=0.3", "train.seed=3"],
        "other_seed": ["loss.constraints=[]", "train.seed=4"],
    }
    firsts, weights = {}, {}
    for name, overrides in variants.items():
        trainer = Trainer(load_config(preset, TINY + overrides), data, tmp_path / name, accelerator="cpu", quiet=True)
        weights[name] = trainer.model.state_dict()
        loader = trainer._loader(0, 0)
        firsts[name] = (list(loader.sampler)[:2], next(iter(loader)))
        trainer.writer.close()
    save_initial_weights(tmp_path / "untrained.pt", load_config(preset, TINY + variants["baseline"]))
    untrained = load_checkpoint(tmp_path / "untrained.pt")["model"]
    for key, value in weights["baseline"].items():
        assert torch.equal(value, weights["all"][key]) and torch.equal(value, untrained[key]), key
    assert any(not torch.equal(v, weights["other_seed"][k]) for k, v in weights["baseline"].items())
    assert firsts["baseline"][0] == firsts["all"][0] != firsts["other_seed"][0]
    batch, other = firsts["baseline"][1], firsts["all"][1]
    assert all(torch.equal(v, other[k]) for k, v in batch.items() if torch.is_tensor(v))  # frames, augmentation


def test_spec_checks_and_bundled_specs(tmp_path):
    """Bundled and experiments/ specs are valid, bundled ones are no training presets; a spec's problems
    name the spec file."""
    for name in ("synth", "kitti_gpu"):
        copy = STUDY_SPECS / f"{name}.yaml"
        spec = load_spec(copy, data_path=tmp_path if name == "kitti_gpu" else None)
        assert spec.reference == "baseline" and spec.seeds == [0, 1, 2]
        assert spec.config("baseline", 2).loss.constraints == [] and spec.config("cyc", 1).train.seed == 1
    assert load_spec(copy, data_path=tmp_path).data["test_split"].endswith("eigen/test_files.txt")
    synth = load_spec(copy.with_name("synth.yaml"))
    # synth_norm's cyc_temporal needs model.constraint_norm, removed: the spec runs at the commit named.
    with pytest.raises(PoseconsError, match="synth_norm.yaml: variant 'cyc_temporal': .* at commit 1be435b"):
        load_spec(EXPERIMENTS / "synth_norm.yaml")
    # synth_ema and synth_dc likewise share study/synth's runs of the variants they name.
    for name, shared in (("synth_ema", ["baseline"]), ("synth_dc", ["baseline", "dc"])):
        other = load_spec(EXPERIMENTS / f"{name}.yaml")
        assert other.data == synth.data and other.preset_file == synth.preset_file
        assert all(other.run_overrides(v, 0) == synth.run_overrides(v, 0) for v in shared)
    # synth_bf16 is study/synth in bf16 with an EMA, nothing else: same data, variants and losses.
    fast = load_spec(EXPERIMENTS / "synth_bf16.yaml")
    assert fast.data == synth.data and list(fast.variants) == list(synth.variants) and fast.seeds == synth.seeds
    for v in synth.variants:
        a, b = fast.config(v, 1), synth.config(v, 1)
        assert (a.train.precision, a.train.ema_decay) == ("bf16", 0.99) and b.train.precision == "32"
        assert a.loss == b.loss and a.model == b.model and a.data == b.data
    # synth_fast is synth_bf16 stopped at 500 steps: its runs are the first 500 steps of synth_bf16's.
    short = load_spec(copy.with_name("synth_fast.yaml"))
    assert short.data == fast.data and list(short.variants) == list(fast.variants) and short.seeds == fast.seeds
    for v in fast.variants:
        a, b = short.config(v, 1), fast.config(v, 1)
        assert a.train.max_steps == 500 < b.train.max_steps and b.train.checkpoint_every == 100
        b.train.max_steps = 500
        assert a.to_dict() == b.to_dict()
    # synth_skip shares synth_fast's runs of baseline and cyc; its new variants add the skip term only.
    skip = load_spec(EXPERIMENTS / "synth_skip.yaml")
    assert skip.data == short.data and all(skip.config(v, 4) == short.config(v, 4) for v in ("baseline", "cyc"))
    for v, base in (("skip", "baseline"), ("skip_cyc", "cyc")):
        a, b = skip.config(v, 4), short.config(base, 4)
        assert a.loss.skip_weight == 1.0 and b.loss.skip_weight == 0
        a.loss.skip_weight = 0
        assert a.to_dict() == b.to_dict()
    scdepth = load_spec(EXPERIMENTS / "synth_scdepth.yaml")
    # synth_scdepth: synth_fast's data and baseline with the step decay; sc05 and sc01 add SC-Depth's term only.
    assert scdepth.data == short.data
    a, b = scdepth.config("lr_decay", 1), short.config("baseline", 1)
    assert a.train.lr_decay_epochs == [6] != b.train.lr_decay_epochs
    a.train.lr_decay_epochs = b.train.lr_decay_epochs
    assert a.to_dict() == b.to_dict()
    for v, weight in (("sc05", 0.5), ("sc01", 0.1)):
        a, b = scdepth.config(v, 1), scdepth.config("lr_decay", 1)
        assert (a.loss.depth_consistency_weight, a.loss.depth_consistency_form) == (weight, "sc_depth")
        a.loss.depth_consistency_weight, a.loss.depth_consistency_form = 0.0, "one_way"
        assert a.to_dict() == b.to_dict()
    # synth_open is synth_fast's recipe on the second benchmark: other data, the same runs' configs.
    second = load_spec(EXPERIMENTS / "synth_open.yaml")
    assert second.data["synth"] == {**short.data["synth"], "profile": "open"}
    assert all(second.config(v, 2) == short.config(v, 2) for v in ("baseline", "cyc", "all"))
    assert second.config("lr_decay", 2) == scdepth.config("lr_decay", 2)
    ema = load_spec(EXPERIMENTS / "synth_ema.yaml")
    assert ema.config("baseline_ema", 0).train.ema_decay == 0.99
    assert ema.config("baseline_ema", 0).loss == synth.config("baseline", 0).loss
    subset = spec.select(["cyc", "baseline"], [3, 4, 5])  # the spec's order: the reference stays first
    assert list(subset.variants) == ["baseline", "cyc"] and subset.runs()[:2] == [("baseline", 3), ("cyc", 3)]
    # Without the reference named, it is kept: the untrained row and the differences are its.
    assert list(spec.select(["all", "id"]).variants) == ["baseline", "id", "all"]
    assert spec.select(None, None) == spec
    with pytest.raises(PoseconsError, match="--variants 'cycle': not in kitti_gpu.yaml"):
        spec.select(["cycle"])
    with pytest.raises(PoseconsError, match="--seeds: seeds must be distinct"):
        spec.select(None, [1, 1])
    assert not any(name.startswith("study/") for name in preset_names())
    with pytest.raises(PoseconsError, match="neither a file nor a bundled preset"):
        resolve_preset("study/synth")
    with pytest.raises(PoseconsError, match="kitti_gpu.yaml: data.path is not set: pass .* --data-path"):
        load_spec("study/kitti_gpu")
    # study/7scenes: the real sequence beside the repository, one frame in five, 620 on held out.
    seven = load_spec("study/7scenes")
    assert Path(seven.data["rgbd"]["input"]) == (Path(__file__).resolve().parents[2] / "shared/real/7scenes").resolve()
    assert seven.threads == 1 and len(seven.seeds) >= 6
    assert seven.config("baseline", 0).model.frame_ids == [0, -1, 1] and seven.config("cyc", 0).data.split == "custom"
    rgbd = dict(seven.data["rgbd"], input=str(tmp_path))
    for change, message in (
        ({"test_form": 5}, "data.rgbd: unknown key 'test_form'"),
        ({"calib": None}, "data.rgbd: missing key 'calib'"),
        ({"every": 0}, r"data.rgbd.every must be an integer ≥ 1, got 0"),
        ({"min_depth": 10}, "data.rgbd: min_depth 10 and max_depth 10 must be 0 < min < max"),
        ({}, f"data.rgbd.calib: {tmp_path}/camera-intrinsics.txt does not exist"),
    ):
        bad = write_spec(tmp_path / "rgbd.yaml", data={"rgbd": {**rgbd, **change}})
        with pytest.raises(PoseconsError, match=f"rgbd.yaml: {message}"):
            load_spec(bad)
    bad = write_spec(tmp_path / "seeded.yaml", variants={"a": ["train.seed=1"]})
    with pytest.raises(PoseconsError, match="seeded.yaml: variant 'a': train.seed is set by seeds:"):
        load_spec(bad)
    bad = write_spec(tmp_path / "kitti.yaml", preset="kitti/baseline")
    with pytest.raises(
        PoseconsError, match="kitti.yaml: variant 'baseline': synthetic data trains on data.split=synth"
    ):
        load_spec(bad)


@pytest.mark.slow
def test_jobs_run_side_by_side_in_worker_processes_and_pass_a_signal_on(tmp_path, capsys):
    # The cyc run keeps an EMA of its weights: its result pairs them with its raw weights.
    variants = {"baseline": ["loss.constraints=[]"], "cyc": ["loss.constraints=[cyc]", "train.ema_decay=0.5"]}
    spec, out = write_spec(tmp_path / "toy.yaml", variants=variants), tmp_path / "study"
    argv = ["study", "--spec", str(spec), "--out", str(out), "--quiet", "--accelerator", "cpu", "--jobs", "2"]
    assert main(argv) == 0
    threads = max(1, torch.get_num_threads() // 2)
    for variant in ("baseline", "cyc"):
        result = json.loads((out / "results" / f"{variant}_seed0.json").read_text())
        assert result["steps"] == 3 and result["environment"]["machine"].endswith(f", {threads} used")
        assert (out / "runs" / variant / "seed0" / "study.log").is_file()
    assert "runs done: 2 of 2" in (out / "results.md").read_text()
    assert capsys.readouterr().out.count("] done ") == 2

    # SIGTERM to the study while both runs of seed 0 train: each saves its state and stops (long before
    # its 400th step: a signal not passed on would let both finish), seed 1's runs never start (the study
    # used to wait for them forever), and the study says how to go on.
    slow_overrides = [*TINY[:1], "train.max_steps=400", *TINY[2:]]
    slow = write_spec(tmp_path / "slow.yaml", overrides=slow_overrides, seeds=[0, 1])
    out = tmp_path / "slow"
    started = out / "runs" / "cyc" / "seed0" / "config.yaml"

    def stop_once_training() -> None:
        while not started.is_file():
            time.sleep(0.2)
        time.sleep(5)  # past the first steps
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=stop_once_training, daemon=True).start()
    argv = ["study", "--spec", str(slow), "--out", str(out), "--quiet", "--accelerator", "cpu", "--jobs", "2"]
    assert main(argv) == 128 + signal.SIGTERM
    assert "stopped by SIGTERM; the runs saved their state" in capsys.readouterr().err
    for variant in ("baseline", "cyc"):
        assert load_checkpoint(out / "runs" / variant / "seed0" / "checkpoints" / "last.pt")["step"] >= 1
        assert not (out / "results" / f"{variant}_seed0.json").exists()
        assert not (out / "runs" / variant / "seed1").exists()


@pytest.mark.slow
def test_an_rgbd_study_trains_on_one_stretch_and_scores_a_later_one_on_its_depth_images(tmp_path, capsys):
    """data.rgbd: the sequence is prepared once with its later stretch held out; each run (in worker
    processes, which get --data-path as well) is scored on that stretch's depth images (dense ground truth in the spec's range, no crop) and poses,
    and the report says so."""
    import numpy as np

    from rgbd_sequence import write_sequence

    source = tmp_path / "seq"
    write_sequence(source, count=14, width=128, height=96)
    np.savetxt(source / "K.txt", [[80, 0, 64], [0, 80, 48], [0, 0, 1]])
    rgbd = {"color": "frame-*.color.png", "depth": "frame-*.depth.png", "poses": "frame-*.pose.txt"}
    rgbd.update(calib="K.txt", depth_scale=1000, test_from=8, gap=2, min_depth=0.1, max_depth=3.0)
    overrides = ["model.height=64", "model.width=128", "model.frame_ids=[0,-1,1]", "data.split=custom"]
    spec = write_spec(tmp_path / "rgbd.yaml", overrides=overrides + TINY[1:], data={"rgbd": rgbd})
    out = tmp_path / "study"
    argv = ["study", "--spec", str(spec), "--out", str(out), "--data-path", str(source), "--quiet", "--jobs", "2"]
    assert main([*argv, "--accelerator", "cpu"]) == 0  # the workers get the sequence's folder too
    cyc = json.loads((out / "results" / "cyc_seed0.json").read_text())
    assert cyc["test_lines"] == [f"custom/custom_drive_0001_sync {k} l" for k in range(6)]  # source frames 8–13
    depth = cyc["depth"]["frame"]
    assert (depth["gt_kind"], depth["crop"], depth["depth_range"]) == ("dense", "none", [0.1, 3.0])
    assert depth["n_frames"] == 6 and np.isfinite(depth["scale_cv"])
    assert set(cyc["pose"]) == {"00"} and cyc["pose"]["00"]["n_frames"] == 6
    report = (out / "results.md").read_text()
    assert "RGB-D sequence" in report and "Garg crop" not in report
    assert "| **mean σ/μ** (primary) | cyc | 1 |" in report and "| cyc | 1 |" in report
    capsys.readouterr()
