"""``posecons study``: every (variant, seed) run of a spec → train → evaluate its last weights → one
JSON each → the report. Rerunning it skips what is done and resumes what was interrupted.

The study folder::

    OUT/data/                          the synthetic data set (specs with data.synth), made once
    OUT/gt/test_depth.npz              ground truth of the test split, exported once
    OUT/untrained/seed<k>.pt           the initial weights of every run with seed k
    OUT/runs/<variant>/seed<k>/        a `posecons train` run directory
    OUT/results/study.json             the spec as last run (variant order, seeds, data)
    OUT/results/<variant>_seed<k>.json one evaluation each, written when it is complete: present = done
    OUT/results/untrained_seed<k>.json the untrained network of seed k, the reference row
    OUT/results/failed/<variant>_seed<k>.*     the error (.json) and traceback (.log) of a failed run
    OUT/results.md, OUT/results/*.png  the report (or --report PATH)
    OUT/.study.lock                    held while a study process prepares the data and reference rows

A run that fails (a crash, a bad frame) does not stop the others: its error line and log are
recorded, the report lists it, and the command exits with status 1 once the rest are done; running
it again retries the failed runs.

Several study processes may share one folder (two terminals, two machines on a shared disk): a run
that another one is training is skipped, and one finished meanwhile is not redone.

Each run evaluates ``checkpoints/last.pt`` — the weights at the last step, chosen without ground
truth — with frame and per-sequence median scaling, and its pose net on every test odometry sequence.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import signal
import subprocess
import sys
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from filelock import FileLock

from ..checkpoint import describe_checkpoint, load_checkpoint
from ..config import Config, config_from_dict
from ..data.gt import export_gt, load_gt
from ..data.splits import SplitLine, read_split
from ..data.synth import generate_synth
from ..data.synth.oracle import oracle_disparities
from ..errors import Interrupted, PoseconsError
from ..evaluation import evaluate
from ..fileio import check_writable, make_dirs, write_json, write_text
from ..inference.backend import Predictor, load_predictor
from ..training.initial_weights import save_initial_weights
from ..training.precision import cpu_kind, processor_name
from ..training.run_dir import run_in_progress
from ..training.trainer import train
from .report import FAILED, STUDY_FILE, read_json, write_report
from .spec import CONSTANT, FLOOR, UNTRAINED, StudySpec

SCALINGS = ("frame", "sequence")


class RunsFailed(PoseconsError):
    """Some runs of a study failed; the others finished."""

    exit_code = 1


def result_name(variant: str, seed: int) -> str:
    return f"{variant}_seed{seed}.json"


@dataclass
class StudyData:
    """Where a study trains and what it is evaluated on."""

    train_path: Path  # data root passed to train
    split: list[SplitLine]  # depth test lines
    gt: Path  # their exported ground truth
    odometry: Path | None  # odometry root with sequences/ and poses/
    sequences: list[str]  # test odometry sequences ("09")
    gt_kind: str = "lidar"  # "dense" for an RGB-D sequence's depth images
    depth_range: tuple[float, float] | None = None  # the valid ground truth (metres); None: KITTI's


class Progress:
    """One line per run start and finish, with the elapsed time and the runs left."""

    def __init__(self, total: int):
        self.start, self.left, self.skipped = time.monotonic(), total, 0

    def line(self, text: str) -> None:
        print(f"[study {(time.monotonic() - self.start) / 60:6.1f} min] {text}", flush=True)

    def taken(self, out: Path, variant: str, seed: int) -> bool:
        """Whether another study process has finished or is training (variant, seed): then skip it."""
        if (out / "results" / result_name(variant, seed)).is_file():
            why = "finished by another process"
        elif run_in_progress(out / "runs" / variant / f"seed{seed}"):
            why = "another process is training it; run this command again later for its result"
        else:
            return False
        self.left, self.skipped = self.left - 1, self.skipped + 1
        self.line(f"skip {variant} seed {seed}: {why} ({self.left} runs left)")
        return True

    def failed(self, variant: str, seed: int, error: str) -> None:
        self.left -= 1
        self.line(f"FAILED {variant} seed {seed}: {error} ({self.left} runs left)")

    def done(self, result: dict, started: float) -> None:
        self.left -= 1
        depth = result["depth"]["frame"]
        self.line(
            f"done {result['variant']} seed {result['seed']} in {(time.monotonic() - started) / 60:.1f} min: "
            f"σ/μ {depth['scale_cv']:.4f}, abs rel {depth['abs_rel']:.3f} ({self.left} runs left)"
        )


def _flat(d: dict, prefix: str = "") -> dict[str, Any]:
    out = {}
    for key, value in d.items():
        out.update(_flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {f"{prefix}{key}": value})
    return out


def config_changes(recorded: dict, wanted: Config) -> list[str]:
    """'key: old → new' for each setting in which a run's recorded config differs from the spec's
    (defaults added since the run count as unchanged; ``pretrained: auto`` matches what it resolved to)."""
    try:
        old = _flat(config_from_dict(recorded).to_dict())
    except PoseconsError as exc:
        return [f"its config is not readable here ({exc})"]
    new = _flat(wanted.to_dict())
    if wanted.model.pretrained == "auto":
        del old["model.pretrained"], new["model.pretrained"]
    return [f"{k}: {old.get(k)!r} → {new.get(k)!r}" for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]


def check_existing(spec: StudySpec, out: Path) -> None:
    """Refuse, before any work, to continue a study folder whose data or runs do not match the spec."""
    study_file = out / "results" / STUDY_FILE
    if study_file.is_file():
        recorded = read_json(study_file).get("data")
        if recorded != spec.data:
            raise PoseconsError(
                f"{out} holds a study of other data ({recorded}, spec: {spec.data}); choose a new --out"
            )
    runs = [(v, s, spec.config(v, s)) for v, s in spec.runs()]
    runs += [(UNTRAINED, s, spec.config(spec.reference, s)) for s in spec.seeds]
    for variant, seed, config in runs:
        result = out / "results" / result_name(variant, seed)
        run_config = out / "runs" / variant / f"seed{seed}" / "config.yaml"
        if result.is_file():
            recorded, where = read_json(result).get("config", {}), result
        elif run_config.is_file():
            recorded, where = yaml.safe_load(run_config.read_text()), run_config
        else:
            continue
        changes = config_changes(recorded, config)
        if changes:
            raise PoseconsError(
                f"{where}: this run has another config than the spec gives it ({'; '.join(changes[:3])}); "
                "choose a new --out, or delete the run and its result to redo it"
            )


def prepare_data(spec: StudySpec, out: Path) -> StudyData:
    """Generate the synthetic data or prepare the RGB-D sequence (once), or take the KITTI roots; export
    the test ground truth once."""
    if "rgbd" in spec.data:
        return _prepare_rgbd(spec.data["rgbd"], out / "data")
    if "synth" in spec.data:
        root = out / "data"
        if not (root / "synth.json").is_file():
            print("[study] generating the synthetic KITTI-format data set", flush=True)
            generate_synth(root, **spec.data["synth"])
        meta = json.loads((root / "synth.json").read_text())
        split = read_split(root / "splits" / "synth" / "test_files.txt")
        odometry, sequences = root / "odometry", list(meta["test_sequences"])
    else:
        root = Path(spec.data["path"])
        split = read_split(spec.data["test_split"])
        odometry = Path(spec.data["odometry"]) if "odometry" in spec.data else None
        sequences = spec.data.get("odometry_sequences", [])
    gt = out / "gt" / "test_depth.npz"
    if not gt.is_file():
        print(f"[study] exporting the ground truth of {len(split)} test frames", flush=True)
        export_gt(root, split, gt)
    return StudyData(root, split, gt, odometry, sequences)


def _prepare_rgbd(args: dict[str, Any], root: Path) -> StudyData:
    """The sequence through prepare-rgbd into ``root`` (once): its test stretch is the test split, with
    its depth images as ground truth and its poses as odometry sequence 00."""
    from ..data.calib import read_intrinsics
    from ..data.rgbd import GT_FILE, SEQUENCE, RGBDSource, prepare_rgbd

    source = Path(args["input"])
    if not (root / "rgbd.json").is_file():
        print(f"[study] preparing the RGB-D sequence {source}", flush=True)
        prepare_rgbd(
            RGBDSource(source, args["color"], args["depth"], args["poses"]),
            root,
            read_intrinsics(source / args["calib"]),
            args["depth_scale"],
            every=args["every"],
            test_from=args["test_from"],
            gap=args["gap"],
        )
    split = read_split(root / "splits" / "custom" / "test_files.txt")
    depth_range = (args["min_depth"], args["max_depth"])
    return StudyData(root, split, root / GT_FILE, root / "odometry", [SEQUENCE], "dense", depth_range)


def _commit() -> str:
    """``git describe`` of the source tree this package runs from, where it is a git checkout."""
    try:
        done = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--tags"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=20,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return done.stdout.strip() if done.returncode == 0 and done.stdout.strip() else "unknown (not a git checkout)"


def environment(accelerator: str) -> dict[str, str]:
    """Code and machine of a run: the report's header, and what pairs a run with another (threads, CPU kind, GPU)."""
    # The compute threads, since a study may run several runs side by side at fewer threads each.
    threads = torch.get_num_threads()
    machine = f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPU threads, {threads} used"
    if accelerator != "cpu" and torch.cuda.is_available():
        machine += f", {torch.cuda.get_device_name()}"
    return {
        "commit": _commit(),
        "machine": machine,
        "threads": threads,
        "cpu": cpu_kind(),
        "processor": processor_name(),
        "python": platform.python_version(),
        "torch": torch.__version__,
    }


def evaluate_weights(checkpoint: Path | Predictor, data: StudyData) -> dict[str, Any]:
    """Depth with both scalings and pose on each test sequence of one checkpoint (or of its networks)."""
    depth = evaluate.checkpoint_depth(
        checkpoint, data.train_path, data.split, data.gt, SCALINGS, data.gt_kind, data.depth_range
    )
    pose = {seq: evaluate.checkpoint_pose(checkpoint, data.odometry, seq) for seq in data.sequences}
    return {"depth": depth, "pose": pose, "test_lines": [str(line) for line in data.split]}


def raw_weights_result(checkpoint: Path, data: StudyData) -> dict[str, Any]:
    """With ``train.ema_decay``, the raw weights of the same step evaluated as the EMA is: the EMA's
    effect paired on one trajectory (experiments/investigation.md §7). Empty for a checkpoint without an EMA."""
    if "raw_model" not in load_checkpoint(checkpoint):
        return {}
    result = evaluate_weights(load_predictor(checkpoint, "auto", entry="raw_model"), data)
    return {"raw_weights": {"depth": result["depth"], "pose": result["pose"]}}


def depth_floor(spec: StudySpec, data: StudyData) -> dict[str, Any]:
    """The renderer's exact depth at the network size, evaluated like a run: what resizing, sparse
    LiDAR and the crop leave of each metric (and of σ/μ) for a perfect depth network."""
    m = spec.config(spec.reference, spec.seeds[0]).model
    disps = oracle_disparities(data.train_path, data.split, m.height, m.width)
    gts, _ = load_gt(data.gt)
    name = f"the renderer's depth at {m.width}×{m.height}"
    depth = {
        s: evaluate.evaluate_depth(disps, gts, data.split, scaling=s, pred_name=name, gt_name=str(data.gt))
        for s in SCALINGS
    }
    return {"variant": FLOOR, "seed": 0, "depth": depth}


def constant_depth(spec: StudySpec, data: StudyData) -> dict[str, Any]:
    """A depth that is the same everywhere, evaluated like a run (frame-median scaling makes it each
    frame's median ground truth): the score of a collapsed run, which a run must beat to have learnt."""
    m = spec.config(spec.reference, spec.seeds[0]).model
    disps = np.ones((len(data.split), m.height, m.width), np.float32)
    gts, _ = load_gt(data.gt)
    depth = {
        s: evaluate.evaluate_depth(
            disps,
            gts,
            data.split,
            data.gt_kind,
            "a constant depth",
            scaling=s,
            gt_name=str(data.gt),
            depth_range=data.depth_range,
        )
        for s in SCALINGS
    }
    return {"variant": CONSTANT, "seed": 0, "depth": depth}


def record_failure(out: Path, variant: str, seed: int, error: str, log: Path) -> str:
    """Write the failure record of (variant, seed) and return its line for the summary."""
    write_json(
        out / "results" / FAILED / result_name(variant, seed),
        {"variant": variant, "seed": seed, "error": error, "log": str(log), "finished": _now()},
    )
    return f"{variant} seed {seed}: {error} (log: {log})"


def _last_line(log: Path) -> str:
    lines = [line.strip() for line in log.read_text(errors="replace").splitlines() if line.strip()]
    return lines[-1] if lines else "no output"


def _train(config: Config, data: StudyData, run_dir: Path, accelerator: str, quiet: bool) -> dict:
    """Train a run, resume an interrupted one, or read the summary of a finished one."""
    summary, last = run_dir / "train_summary.json", run_dir / "checkpoints" / "last.pt"
    if summary.is_file() and last.is_file():
        return json.loads(summary.read_text())
    return train(config, data.train_path, run_dir, resume=last.is_file(), accelerator=accelerator, quiet=quiet)


def train_and_evaluate(
    spec: StudySpec, data: StudyData, out: Path, variant: str, seed: int, accelerator: str, quiet: bool, env: dict
) -> dict[str, Any]:
    """Train (or resume) the run (variant, seed), evaluate its last weights and write its result JSON."""
    run_dir = out / "runs" / variant / f"seed{seed}"
    try:
        summary = _train(spec.config(variant, seed), data, run_dir, accelerator, quiet)
    except Interrupted as exc:  # its state is in last.pt once the loop began; the study resumes it
        signum = exc.exit_code - 128
        raise Interrupted(
            f"stopped by {signal.Signals(signum).name} during {variant} seed {seed}; run the same "
            "`posecons study` command again to continue",
            signum,
        ) from None
    last = run_dir / "checkpoints" / "last.pt"
    result = {
        "variant": variant,
        "seed": seed,
        "overrides": spec.run_overrides(variant, seed),
        "config": yaml.safe_load((run_dir / "config.yaml").read_text()),
        "checkpoint": describe_checkpoint(last),
        "train_minutes": summary["minutes"],
        "steps": summary["steps"],
        **evaluate_weights(last, data),
        **raw_weights_result(last, data),
        "environment": env,
        "finished": _now(),
    }
    write_json(out / "results" / result_name(variant, seed), result)
    (out / "results" / FAILED / result_name(variant, seed)).unlink(missing_ok=True)
    return result


def _run_side_by_side(
    spec: StudySpec, out: Path, todo: list[tuple[str, int]], jobs: int, accelerator: str, progress: Progress, refresh
) -> list[str]:
    """``todo`` with ``jobs`` runs at a time, each in a process of its own (``python -m
    posecons.study.worker``) with the CPU threads shared out: on two cores two one-thread runs get
    more done than one two-thread run, whose threads wait on each other. A signal is passed on to the
    runs (in sessions of their own, so a terminal's Ctrl-C reaches them once), which save and stop.
    Returns a line for each run that failed."""
    threads = spec.threads or max(1, torch.get_num_threads() // jobs)
    unsignalled: dict[tuple[str, int], subprocess.Popen] = {}  # the running runs no signal has reached
    stopped: list[int] = []
    lock = threading.Lock()  # the progress lines and counts, shared by the lanes and this thread

    def forward(signum: int, frame: Any) -> None:
        stopped.append(signum)
        for run in list(unsignalled):
            # the dict's pop is atomic: of this handler and a lane that has just started the run, one signals it
            proc = unsignalled.pop(run, None)
            if proc is not None:
                proc.send_signal(signum)

    def lane(variant: str, seed: int) -> tuple[int, Path, float] | None:
        """Start the run (unless the study stopped, or another process has it) and wait for it to end."""
        with lock:
            if stopped or progress.taken(out, variant, seed):
                return None
            run_dir = out / "runs" / variant / f"seed{seed}"
            run_dir.mkdir(parents=True, exist_ok=True)
            log = open(run_dir / "study.log", "a")  # noqa: SIM115 (closed when the run ends)
            job = {  # worker.run's arguments; the data roots as the spec resolved them (--data-path included)
                "spec": str(spec.file),
                "out": str(out),
                "variant": variant,
                "seed": seed,
                "accelerator": accelerator,
                "data_path": spec.data.get("path") or spec.data.get("rgbd", {}).get("input"),
                "odometry_path": spec.data.get("odometry"),
            }
            command = [sys.executable, "-m", "posecons.study.worker", json.dumps(job)]
            env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
            proc = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
            unsignalled[variant, seed], started = proc, time.monotonic()
            progress.line(f"start {variant} seed {seed} → {run_dir}, {threads} thread(s) ({progress.left} runs left)")
        if stopped and unsignalled.pop((variant, seed), None):  # a signal came before the run was listed
            proc.send_signal(stopped[0])
        with log:
            proc.wait()
        unsignalled.pop((variant, seed), None)
        return proc.returncode, Path(log.name), started

    # The pool's threads only start the runs' processes and wait for them: the runs are not the workers
    # of a ProcessPoolExecutor, which share the study's session (a Ctrl-C would reach a run twice, from
    # the terminal and passed on, and a second signal stops a run at once, not at a step boundary), keep
    # their pids to themselves (nothing to pass a signal on to), and break the pool, failing every other
    # run, when one of them dies (killed, out of memory).
    failed: list[str] = []
    previous = {s: signal.signal(s, forward) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with ThreadPoolExecutor(jobs) as pool:
            lanes = {pool.submit(lane, variant, seed): (variant, seed) for variant, seed in todo}
            for future in as_completed(lanes):
                ended = future.result()
                if ended is None:
                    continue
                (variant, seed), (code, log, started) = lanes[future], ended
                if code == 0:
                    with lock:
                        progress.done(read_json(out / "results" / result_name(variant, seed)), started)
                    refresh()
                elif not stopped:
                    error = f"exit status {code}: {_last_line(log)}"
                    failed.append(record_failure(out, variant, seed, error, log))
                    with lock:
                        progress.failed(variant, seed, error)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    if stopped:
        raise Interrupted(
            f"stopped by {signal.Signals(stopped[0]).name}; the runs saved their state: run the same "
            "`posecons study` command again to continue",
            stopped[0],
        )
    return failed


@contextlib.contextmanager
def compute_threads(threads: int | None):
    """torch's compute threads set to ``threads`` (when given) inside the block, restored after it."""
    previous = torch.get_num_threads()
    if threads:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def run_study(
    spec: StudySpec,
    out: Path,
    report: Path,
    publish: bool = False,
    accelerator: str = "auto",
    quiet: bool = False,
    jobs: int = 1,
) -> int:
    """Every missing run of ``spec`` into ``out``, ``jobs`` at a time, rewriting ``report``
    (:func:`.report.write_report`, ``publish`` as there) after each one; returns the number of runs
    trained or resumed (not those another process finished or is training)."""
    check_existing(spec, out)
    results = out / "results"

    def refresh() -> None:
        write_report(results, report, spec.describe(), publish)

    with compute_threads(spec.threads):  # the reference rows and in-process runs
        env = environment(accelerator)
        check_writable(out, folder=True)
        make_dirs(out)
        with FileLock(out / ".study.lock"):  # one process makes the data and the reference rows
            data = _prepare(spec, out, env)
        done = [r for r in spec.runs() if (results / result_name(*r)).is_file()]
        todo = [r for r in spec.runs() if r not in done]
        progress = Progress(len(todo))
        progress.line(f"{len(done)} of {len(spec.runs())} runs done before, {len(todo)} to go")
        on_cpu = accelerator == "cpu" or not torch.cuda.is_available()
        if on_cpu and env["cpu"].endswith("emulated") and any(spec.config(*r).train.precision == "bf16" for r in todo):
            progress.line(
                f"warning: the runs compute in bf16, which this CPU ({env['cpu']}) emulates: each takes several "
                "times as long as in fp32, and the report pairs them only with runs on this kind of CPU"
            )

        failed = _run_side_by_side(spec, out, todo, jobs, accelerator, progress, refresh) if jobs > 1 else []
        for variant, seed in todo if jobs == 1 else []:
            if progress.taken(out, variant, seed):
                continue
            run_dir = out / "runs" / variant / f"seed{seed}"
            progress.line(f"start {variant} seed {seed} → {run_dir} ({progress.left} runs left)")
            started = time.monotonic()
            try:
                result = train_and_evaluate(spec, data, out, variant, seed, accelerator, quiet, env)
            except Interrupted:
                raise
            except Exception as exc:  # the next run goes on; the record keeps the error and its traceback
                error = "".join(traceback.format_exception_only(exc)).strip().splitlines()[-1]
                log = out / "results" / FAILED / f"{variant}_seed{seed}.log"
                write_text(log, "".join(traceback.format_exception(exc)))
                failed.append(record_failure(out, variant, seed, error, log))
                progress.failed(variant, seed, error)
                continue
            progress.done(result, started)
            refresh()
        if progress.skipped or failed or not todo:  # else the last run's refresh wrote it
            refresh()
        if failed:
            raise RunsFailed(
                f"{len(failed)} of {len(todo)} runs failed (the others finished; run the same command again to "
                "retry them): " + "; ".join(failed)
            )
        return len(todo) - progress.skipped


def _prepare(spec: StudySpec, out: Path, env: dict[str, str]) -> StudyData:
    """The data, the test ground truth, and the reference rows (each seed's untrained network, the
    renderer's depth) that a study folder needs before its runs; each is made once."""
    results = out / "results"
    write_json(results / STUDY_FILE, spec.describe())
    data = prepare_data(spec, out)
    for seed in spec.seeds:  # the reference row: the initial weights every run of the seed starts from
        target = results / result_name(UNTRAINED, seed)
        if not target.is_file():
            weights = out / "untrained" / f"seed{seed}.pt"
            config = spec.config(spec.reference, seed)
            save_initial_weights(weights, config)
            result = {"variant": UNTRAINED, "seed": seed, "overrides": spec.run_overrides(spec.reference, seed)}
            result.update(config=config.to_dict(), checkpoint=describe_checkpoint(weights), train_minutes=0, steps=0)
            write_json(target, {**result, **evaluate_weights(weights, data), "environment": env, "finished": _now()})
            print(f"[study] evaluated the untrained network of seed {seed}", flush=True)

    floor = results / result_name(FLOOR, 0)
    if "synth" in spec.data and not floor.is_file():
        write_json(floor, {**depth_floor(spec, data), "environment": env, "finished": _now()})
        print("[study] evaluated the renderer's own depth (the floor of every depth metric)", flush=True)
    constant = results / result_name(CONSTANT, 0)
    if not constant.is_file():
        write_json(constant, {**constant_depth(spec, data), "environment": env, "finished": _now()})
    return data


def _now() -> str:
    return datetime.now().astimezone().isoformat(timespec="seconds")
