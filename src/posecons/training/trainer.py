"""Training on one CPU, one GPU, or many GPUs and nodes with plain ``torch.distributed``.

Multi-process runs are launched by ``torchrun`` (``posecons train --devices N`` starts it for
you on one node); each process reads ``RANK``/``WORLD_SIZE``/``LOCAL_RANK`` from the environment
that torchrun sets. The run directory holds everything of a run::

    RUN/config.yaml             resolved config
    RUN/checkpoints/last.pt     model, optimiser, scheduler, step, epoch, data position, RNG
                                (with train.ema_decay > 0: "model" is the EMA, "raw_model" the trained weights)
    RUN/checkpoints/last.prev.pt the last.pt before it: --resume falls back to it if last.pt does not load
    RUN/checkpoints/epoch_NN.pt weights (+ config, step) at each epoch end; train.keep_epochs of them
    RUN/checkpoints/best.pt     weights at the best validation abs rel (photometric loss without GT)
    RUN/tb/                     TensorBoard scalars and images
    RUN/metrics/step_NNNNNN.json and RUN/metrics.jsonl   one record per validation

Resume is exact: the data order of an epoch is a pure function of (seed, epoch), augmentation
draws of (seed, epoch, index), and the RNG states are saved (:mod:`.resume`), so an interrupted
run that is resumed ends with the same weights as an uninterrupted one (in deterministic mode).
SIGINT or SIGTERM stops the run at the next step boundary with ``last.pt`` written (:mod:`.signals`).
A run that fails or is stopped before it saved any state leaves a new or empty run folder as it
was, but for a crash in training (no bad input): ``RUN/crash.log`` and ``RUN/tb/`` stay (:mod:`.run_dir`).
"""

from __future__ import annotations

import contextlib
import math
import signal
import sys
import time
from pathlib import Path
from typing import Any

import torch
import torch.distributed as dist
import yaml
from torch.nn.parallel import DistributedDataParallel
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from torch.utils.data import DataLoader
from tqdm import tqdm

from ..checkpoint import save_checkpoint
from ..config import Config
from ..data.augment import jitter_batch
from ..data.datasets import build_dataset, split_files
from ..data.frames import EpochOrder
from ..errors import Interrupted, PoseconsError
from ..fileio import keep_copy, write_json, write_text
from ..model import PoseConsModel
from .collapse import CollapseWatch, collapse_signs
from .distributed import Dist, finish_distributed, init_distributed, validation_group, wait_for_validation
from .initial_weights import initial_model, without_imagenet
from .precision import adam, autocast, resolve_precision, use_deterministic_algorithms
from .resume import PREVIOUS, restore_training_state, state_to_resume, training_state
from .run_dir import hold_run_dir, prepare_run_dir, write_crash_record
from .signals import StopRequest
from .train_log import log_step, log_validation, logs_scalars, open_log
from .validation import Validator, describe_selection
from .warmup import warmed_up, warmup_factor


class Trainer:
    """One process's part of a run, in the order it happens: ``__init__`` sets up devices, data,
    validation, model and optimiser (or restores a resumed run), :meth:`fit` runs the steps, with
    validation and checkpoints at their intervals; :func:`train` wraps it in the run folder's lock."""

    def __init__(
        self,
        config: Config,
        data_path: str | Path,
        out: str | Path,
        split_dir: str | Path | None = None,
        resume: bool = False,
        accelerator: str = "auto",
        quiet: bool = False,
    ):
        self.config, self.out = config, Path(out)
        t = config.train
        self.env, self.device = init_distributed(accelerator)
        if self.env.main:
            prepare_run_dir(self.out, resume)
        self.quiet = quiet or not self.env.main
        self.precision, why = resolve_precision(t.precision, self.device)
        if t.deterministic:
            use_deterministic_algorithms(self.device)

        train_file, val_file = split_files(config, data_path, split_dir)
        self.train_set = build_dataset(config, data_path, train_file, train=True)
        self._train_loader: DataLoader | None = None  # made on first use, then serves every epoch
        if len(self.train_set) < t.batch_size * self.env.world:
            raise PoseconsError(
                f"{train_file}: {len(self.train_set)} samples are fewer than one batch "
                f"({t.batch_size} × {self.env.world} processes): lower train.batch_size or use "
                "more data (`posecons synth` prints how many training lines it wrote)"
            )
        # Validation (and its one-off ground-truth export) happens on the main rank only; the others wait.
        validates = bool(val_file) and t.val_every != "off"
        self.validator = (
            Validator(config, data_path, val_file, self.out, self.device) if validates and self.env.main else None
        )
        self._validation_wait = validation_group(self.env) if validates else None
        if t.best_metric == "abs_rel" and self.validator is not None and self.validator.gt is None:
            raise PoseconsError(
                "train.best_metric=abs_rel selects best.pt by ground truth, but the validation split "
                f"{val_file} has no LiDAR scans; use train.best_metric=val_photometric"
            )

        # A resumed run takes its weights from last.pt: nothing is downloaded, so it also resumes offline.
        model = initial_model(without_imagenet(config) if resume else config, t.seed + self.env.rank).to(self.device)
        if not resume:  # the run's config says what "auto" resolved to
            config.model.pretrained = model.initialisation.startswith("ImageNet")
        self.initialisation = model.initialisation
        if t.sync_bn and self.env.world > 1:  # the pose net keeps its per-pair-group statistics
            model.depth_net = torch.nn.SyncBatchNorm.convert_sync_batchnorm(model.depth_net)
        self.model = model
        # The weight EMA follows the unwrapped model on the main rank, which validates and saves.
        self.ema = (
            AveragedModel(model, multi_avg_fn=get_ema_multi_avg_fn(t.ema_decay), use_buffers=True)
            if t.ema_decay > 0 and self.env.main
            else None
        )
        self.weights = f"EMA (decay {t.ema_decay:g})" if t.ema_decay > 0 else "raw"  # what checkpoints hold
        self.ddp = (
            DistributedDataParallel(
                model,
                device_ids=[self.device.index] if self.device.type == "cuda" else None,
                find_unused_parameters=config.model.known_motion,  # the pose net then has no gradient
            )
            if self.env.world > 1
            else model
        )
        self.optimizer = adam(model.parameters(), t.lr, self.device)
        self.scheduler = torch.optim.lr_scheduler.MultiStepLR(self.optimizer, t.lr_decay_epochs, t.lr_decay)
        self.scaler = torch.amp.GradScaler(self.device.type, enabled=self.precision == "16")
        self.steps_per_epoch = len(self.train_set) // (t.batch_size * self.env.world * t.grad_accum)
        self.step = self.epoch = self.batch_in_epoch = self.bad_steps = self.skipped_steps = 0
        self.best = math.inf  # best validation value of train.best_metric so far
        self.seconds_before = 0.0  # training time of the earlier sessions of a resumed run
        self.session_start = time.time()
        self.stop = StopRequest()  # `train` installs it as the signal handler
        if resume:
            restore_training_state(self, *state_to_resume(self.out / "checkpoints", self.device, self.env.main))
        elif self.env.main:
            write_text(self.out / "config.yaml", yaml.safe_dump(config.to_dict(), sort_keys=False))
        if not self.quiet:
            print(
                f"initialisation: {self.initialisation}; best.pt selected by {describe_selection(t.best_metric)}"
                + (f"; validation and checkpoints use the {self.weights} weights" if self.ema else "")
                + f"; precision {self.precision}"
                + (f" ({why})" if why else "")
            )
        self.writer = open_log(self.out) if self.env.main else None
        self.collapse = CollapseWatch(start=max(t.warmup_steps, 1))

    # ------------------------------------------------------------------ loop
    def fit(self) -> dict[str, Any]:
        total = self.total_steps()
        bar = tqdm(total=total, initial=self.step, disable=self.quiet, dynamic_ncols=True, unit="step")
        last_metrics = {}
        self.session_start = time.time()
        self.ddp.train()
        self.stop.in_loop = True
        try:
            last_metrics = self._loop(total, bar)
        except Exception:
            if self.stop.signum:  # a DataLoader worker that the same signal ended broke the loop
                self._stop_now()
            raise
        finally:
            self.stop.in_loop = False
            bar.close()
        if self._val_steps and self.step % self._val_steps:
            last_metrics = self.validate()
        seconds = time.time() - self.session_start
        summary = {
            "steps": self.step,
            "epochs": self.epoch,
            "skipped_steps": self.skipped_steps,
            "minutes": (self.seconds_before + seconds) / 60,
            "minutes_this_session": seconds / 60,
            "initialisation": self.initialisation,
            "weights": self.weights,
            "precision": self.precision,
            "best_metric": self.config.train.best_metric,
            "last_validation": last_metrics,
            "collapse": self.collapse.summary(),
        }
        for problem in summary["collapse"]["problems"]:
            print(f"warning: at the end of training {problem}: the depth has collapsed", file=sys.stderr)
        if self.writer:
            self.writer.close()
        return summary

    def total_steps(self) -> int:
        t = self.config.train
        full = self.steps_per_epoch * t.epochs
        return min(full, t.max_steps) if t.max_steps else full

    def _loop(self, total: int, bar) -> dict[str, Any]:
        """The epochs and steps from the current position to ``total``; returns the last validation."""
        t, last_metrics = self.config.train, {}
        while self.step < total and self.epoch < t.epochs:
            micro = 0
            for batch in self._loader(self.epoch, self.batch_in_epoch * t.grad_accum):
                losses, outputs = self._micro_step(batch, last=(micro + 1) % t.grad_accum == 0)
                micro += 1
                if micro % t.grad_accum:
                    continue
                self.batch_in_epoch += 1
                self.step += 1
                bar.update(1)
                if losses is not None:
                    bar.set_postfix({k: f"{v:.3g}" for k, v in losses.items()}, refresh=False)
                    self._log(losses, batch, outputs)
                if self._val_steps and self.step % self._val_steps == 0:
                    last_metrics = self.validate()
                if t.checkpoint_every and self.step % t.checkpoint_every == 0:
                    self.save()
                if self._stop_requested():
                    self._stop_now()
                if self.step >= total or self.batch_in_epoch >= self.steps_per_epoch:
                    break
            if self.batch_in_epoch >= self.steps_per_epoch:  # epoch complete
                self.epoch += 1
                self.batch_in_epoch = 0
                self.scheduler.step()
                if t.val_every == "epoch":
                    last_metrics = self.validate()
                self._save_epoch()
            self.save()
        return last_metrics

    @property
    def _val_steps(self) -> int:
        """Steps between validations; 0 when validation is per epoch or off."""
        every = self.config.train.val_every
        return every if isinstance(every, int) else 0

    def _loader(self, epoch: int, skip_batches: int) -> DataLoader:
        """This rank's batches of ``epoch``, from batch ``skip_batches`` on (a resumed epoch). One loader
        serves every epoch, so its workers persist; the sampler tells them the epoch."""
        t = self.config.train
        if self._train_loader is None:
            workers = self.config.data.num_workers
            self._train_loader = DataLoader(
                self.train_set,
                batch_size=t.batch_size,
                sampler=EpochOrder(self.train_set, self.env.world, self.env.rank, t.seed),
                drop_last=True,
                num_workers=workers,
                pin_memory=self.device.type == "cuda",
                persistent_workers=workers > 0,
                # The loader's own generator keeps worker seeding off the global RNG stream (exact resume).
                generator=torch.Generator().manual_seed(t.seed),
            )
        self._train_loader.sampler.start(epoch, skip_batches * t.batch_size)
        return self._train_loader

    def _micro_step(self, batch: dict, last: bool) -> tuple[dict[str, float] | None, dict]:
        """Forward/backward of one micro-batch; the optimiser steps on the last of ``grad_accum``.

        Returns the loss values (None until the optimiser stepped, or when the step was skipped)
        and the model outputs, which the image log reuses.
        """
        t = self.config.train
        batch = jitter_batch(
            {k: v.to(self.device, non_blocking=True) if torch.is_tensor(v) else v for k, v in batch.items()}
        )
        sync = last or self.env.world == 1
        context = self.ddp.no_sync() if not sync and hasattr(self.ddp, "no_sync") else contextlib.nullcontext()
        with context:
            with autocast(self.precision, self.device):
                outputs, losses = self.ddp(batch, step=self.step)
            finite = torch.isfinite(losses["total"]).float()
            if self.env.world > 1:  # every rank must agree to skip, or DDP would hang
                dist.all_reduce(finite, op=dist.ReduceOp.MIN)
            if finite.item() == 0:
                self._skip_step()
                return None, outputs
            self.scaler.scale(losses["total"] / t.grad_accum).backward()
        if not last:
            return None, outputs
        with warmed_up(self.optimizer, self.scheduler, warmup_factor(self.step + 1, t.warmup_steps)):
            self.scaler.step(self.optimizer)
        self.scaler.update()
        if self.ema is not None:  # AveragedModel's first update copies the weights, then ema ← d·ema + (1 − d)·w
            self.ema.update_parameters(self.model)
        self.optimizer.zero_grad(set_to_none=True)
        self.bad_steps = 0
        return {k: float(v.detach()) for k, v in losses.items()}, outputs

    def _skip_step(self) -> None:
        self.optimizer.zero_grad(set_to_none=True)
        self.bad_steps += 1
        self.skipped_steps += 1
        if self.bad_steps >= self.config.train.max_bad_steps:
            self.save()
            raise PoseconsError(
                f"the loss was not finite for {self.bad_steps} steps in a row (step {self.step}); "
                f"the last good state is in {self.out / 'checkpoints' / 'last.pt'}. "
                "Try a lower train.lr or train.precision=32"
            )

    def _log(self, losses: dict[str, float], batch: dict, outputs: dict) -> None:
        if not self.writer:
            return
        signs = collapse_signs(outputs) if logs_scalars(self.config.train, self.step) else None
        if signs is not None:
            for problem in self.collapse.update(self.step, signs):
                tqdm.write(f"warning: step {self.step}: {problem}; the depth may have collapsed", file=sys.stderr)
        # the rate that the step just taken used, warm-up included
        lr = self.optimizer.param_groups[0]["lr"] * warmup_factor(self.step, self.config.train.warmup_steps)
        log_step(self.writer, self.config.train, self.step, losses, lr, batch, outputs, signs)

    def _stop_requested(self) -> bool:
        """True once a signal asked to stop; every rank must agree, or the others would wait forever."""
        if self.env.world > 1:
            flag = torch.tensor([self.stop.signum], device=self.device)
            dist.all_reduce(flag, op=dist.ReduceOp.MAX)
            self.stop.signum = int(flag.item())
        return bool(self.stop.signum)

    def _stop_now(self) -> None:
        self.save()
        name = signal.Signals(self.stop.signum).name
        raise Interrupted(
            f"stopped by {name} at step {self.step}; the state is saved in "
            f"{self.out / 'checkpoints' / 'last.pt'}: continue with the same command plus --resume",
            self.stop.signum,
        )

    # ------------------------------------------------------------------ validation
    def validate(self) -> dict[str, Any]:
        """Validate on the main rank while the other ranks wait."""
        metrics = self._validate_here() if self.validator else {}
        wait_for_validation(self._validation_wait)
        return metrics

    def _validate_here(self) -> dict[str, Any]:
        """Validate; keep ``checkpoints/best.pt`` at the best score so far."""
        metrics = self.validator.run(self.eval_model, self.step)
        self.model.train()
        if not metrics:
            return metrics
        if self.writer:
            log_validation(self.writer, self.step, metrics)
        score = metrics[self.config.train.best_metric]
        if score < self.best:
            self.best = score
            self.save_weights("best.pt", selected_by=self.config.train.best_metric)
        return metrics

    # ------------------------------------------------------------------ checkpoints
    @property
    def eval_model(self) -> PoseConsModel:
        """The weights that validation and every checkpoint's "model" hold: the EMA when it is on."""
        return self.ema.module if self.ema is not None else self.model

    def save(self) -> None:
        """The full training state, for resuming: ``checkpoints/last.pt``; the one it replaces stays
        as ``last.prev.pt``, what a resume falls back to should the newest not load."""
        if self.env.main:
            last = self.out / "checkpoints" / "last.pt"
            if last.is_file():
                keep_copy(last, last.with_name(PREVIOUS))
            save_checkpoint(last, training_state(self))

    def save_weights(self, name: str, selected_by: str | None = None) -> None:
        """Weights, config and step only — a third of ``last.pt``, enough to evaluate or predict.
        ``selected_by`` says how a selected checkpoint (best.pt) was chosen."""
        if self.env.main:
            save_checkpoint(
                self.out / "checkpoints" / name,
                {
                    "config": self.config.to_dict(),
                    "model": self.eval_model.state_dict(),
                    "weights": self.weights,
                    "step": self.step,
                    "epoch": self.epoch,
                    "best": self.best,
                    "selected_by": selected_by,
                    "initialisation": self.initialisation,
                },
            )

    def _save_epoch(self) -> None:
        keep = self.config.train.keep_epochs
        if keep == 0 or not self.env.main:
            return
        self.save_weights(f"epoch_{self.epoch:02d}.pt")
        if keep > 0:
            snapshots = sorted((self.out / "checkpoints").glob("epoch_*.pt"), key=lambda p: int(p.stem[6:]))
            for old in snapshots[:-keep]:
                old.unlink()


def train(config: Config, data_path: str | Path, out: str | Path, **options: Any) -> dict[str, Any]:
    """Train a run and return a summary (steps, minutes, last validation metrics); ``options`` are
    :class:`Trainer`'s (split_dir, resume, accelerator, quiet)."""
    out = Path(out)
    main = Dist.from_environment().main
    stop = StopRequest()
    with stop.installed():
        with hold_run_dir(out) if main else contextlib.nullcontext() as fresh:
            trainer = Trainer(config, data_path, out, **options)
            trainer.stop = stop
            try:
                summary = trainer.fit()
            except Exception as exc:  # bad input (one line, exit 2) and interrupts are no crash: no record
                if fresh and not isinstance(exc, PoseconsError) and not (out / "checkpoints" / "last.pt").exists():
                    write_crash_record(out, trainer.step, exc, trainer.writer)
                raise
            if trainer.env.main:
                write_json(out / "train_summary.json", summary)
    finish_distributed()
    return summary
