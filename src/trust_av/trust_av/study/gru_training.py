"""Training data and seeded, deterministic training of the GRU plan estimator.

Data: closed-loop TAC-CA runs of the in-process simulator on the *training*
traces (UDDS, HWFET, WLTC 3b; never the evaluation traces) for several alphas. A sample at
step t pairs the H observations the predictor had (steps t-H .. t-1: gap, relative speed,
headway, executed AV acceleration; computed by the planner's own ``observe``) with the N
accelerations the AV then executed (t .. t+N-1). Validation is a contiguous block at the
end of every trace (the same block for every alpha, so no road segment is in both splits).
Normalisation statistics come from the training split only and are stored with the model.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import json
import math
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from preceding_traffic.sources import load_trace
from preceding_traffic.traces import TRAINING_TRACES
from trust_av.study.pinned_numerics import numerics_report
from trust_av.study.workers import worker_pool
from trust_av.system.closed_loop import simulate
from trust_av.system.config import RunConfig
from trust_av.system.metrics import StepRecord
from trust_av_common.kinematics import VehicleState
from trust_av_common.output_files import replacing
from trust_av_planner.planner import observe
from trust_av_planner.predictors.gru import FEATURES, GruConfig, GruWeights, gru_forward

__all__ = ['TrainingSettings', 'build_dataset', 'samples_from_run', 'save_model', 'train',
           'train_with_dagger']


@dataclass(frozen=True)
class TrainingSettings:
    """Hyper-parameters (documented in docs/GRU.md)."""

    traces: tuple[str, ...] = TRAINING_TRACES
    alphas: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
    history_steps: int = 10
    hidden: int = 16
    epochs: int = 40
    batch_size: int = 128
    learning_rate: float = 3e-3
    validation_fraction: float = 0.2
    seed: int = 7
    dagger_rounds: int = 2
    patience: int = 5  # stop after this many epochs without a better validation RMSE; 0: never


@dataclass
class Dataset:
    """Samples: inputs (samples, H, 4), targets (samples, N), and which split they are in."""

    inputs: np.ndarray
    targets: np.ndarray
    validation: np.ndarray
    ca_predictions: np.ndarray
    dt_s: float  # control step of the runs


ARRAY_FIELDS = ('inputs', 'targets', 'validation', 'ca_predictions')


def samples_from_run(records: Sequence[StepRecord], history: int, horizon: int,
                     length_m: float, headway_cap_s: float) -> tuple[np.ndarray, np.ndarray,
                                                                     np.ndarray, np.ndarray]:
    """(inputs, targets, step index, CA prediction) of one closed-loop run."""
    obs = []
    for k in range(len(records) - 1):
        after = records[k + 1]
        o = observe(VehicleState(after.av_position_m, after.av_speed_mps),
                    VehicleState(after.human_position_m, after.human_speed_mps),
                    records[k].av_accel_mps2, length_m, headway_cap_s)
        obs.append([o.gap_m, o.relative_speed_mps, o.time_headway_s, o.av_accel_mps2])
    observations = np.array(obs)
    executed = np.array([r.av_accel_mps2 for r in records])
    xs, ys, steps, ca = [], [], [], []
    for t in range(history, len(records) - horizon + 1):
        xs.append(observations[t - history:t])
        ys.append(executed[t:t + horizon])
        steps.append(t)
        ca.append(np.full(horizon, executed[t - 1]))
    return np.array(xs), np.array(ys), np.array(steps), np.array(ca)


def run_samples(config: RunConfig, settings: TrainingSettings, trace_name: str, alpha: float,
                predictor: str = 'ca', gru_model: str | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One closed-loop run of the dataset: (inputs, targets, validation flag, CA prediction)."""
    trace = load_trace(trace_name, config.planner.dt_s, config.trace)
    cut = int(trace.steps * (1.0 - settings.validation_fraction))
    run_config = dataclasses.replace(config, planner=dataclasses.replace(
        config.planner, alpha=alpha, predictor=predictor))
    if gru_model is not None:
        run_config = dataclasses.replace(run_config, predictor_configs=(
            *((n, c) for n, c in config.predictor_configs if n != 'gru'),
            ('gru', GruConfig(gru_model))))
    records = simulate(run_config, trace).records
    x, y, steps, ca = samples_from_run(records, settings.history_steps,
                                       config.planner.horizon_steps,
                                       config.shared.vehicle_length_m,
                                       config.planner.time_headway_cap_s)
    # Train: every step a sample touches (t-H .. t+N-1) is before the cut;
    # validation: every step after it; samples across the cut are dropped.
    horizon = config.planner.horizon_steps
    validation = steps - settings.history_steps >= cut
    keep = validation | (steps + horizon - 1 < cut)
    return x[keep], y[keep], validation[keep], ca[keep]


def build_dataset(config: RunConfig, settings: TrainingSettings,
                  on_run: Callable[[int, int], None] | None = None,
                  predictor: str = 'ca', gru_model: str | None = None,
                  pool: Executor | None = None) -> Dataset:
    """Run TAC-CA (or TAC-GRU with ``gru_model``) on every training trace and alpha; split
    by trace segment.

    With ``pool`` the runs go to its worker processes (each run is independent and the
    samples are assembled in the same order, so the dataset is the same bit for bit; the
    workers inherit this process's environment, hence its pinned numerics).
    """
    cases = [(name, alpha) for name in settings.traces for alpha in settings.alphas]
    parts: list[tuple[np.ndarray, ...]] = []
    if pool is None:
        for done, (name, alpha) in enumerate(cases, start=1):
            parts.append(run_samples(config, settings, name, alpha, predictor, gru_model))
            if on_run is not None:
                on_run(done, len(cases))
    else:
        futures = [pool.submit(run_samples, config, settings, name, alpha, predictor,
                               gru_model) for name, alpha in cases]
        for done, future in enumerate(futures, start=1):
            parts.append(future.result())
            if on_run is not None:
                on_run(done, len(cases))
    arrays = {name: np.concatenate([p[i] for p in parts])
              for i, name in enumerate(ARRAY_FIELDS)}
    return Dataset(**arrays, dt_s=config.planner.dt_s)


def merge(a: Dataset, b: Dataset) -> Dataset:
    """Both datasets' samples (runs at the same control step)."""
    if a.dt_s != b.dt_s:
        raise ValueError(f'cannot merge datasets at dt_s {a.dt_s} and {b.dt_s} s')
    arrays = {name: np.concatenate([getattr(a, name), getattr(b, name)])
              for name in ARRAY_FIELDS}
    return Dataset(**arrays, dt_s=a.dt_s)


def train_with_dagger(config: RunConfig, settings: TrainingSettings, work_dir: Path,
                      on_stage: Callable[[str], None] | None = None,
                      on_epoch: Callable[[int, int], None] | None = None,
                      jobs: int = 1) -> tuple[GruWeights, dict[str, Any]]:
    """TAC-CA data, then ``dagger_rounds`` rounds of aggregation (Ross et al., 2011).

    A GRU trained on TAC-CA runs only is used in a loop it has never seen: with alpha > 0
    the AV leans towards the GRU's prediction, and the prediction is made from the AV's own
    past, so errors feed back. Each round runs TAC-GRU with the current model on the same
    *training* traces, adds those samples and retrains from scratch with the same seed.
    ``jobs`` > 1 runs the closed loops in that many worker processes (same result).
    """
    def stage(name: str) -> None:
        if on_stage is not None:
            on_stage(name)

    with contextlib.ExitStack() as stack:
        pool = None
        if jobs > 1:
            pool = stack.enter_context(worker_pool(jobs))
        stage('TAC-CA runs on the training traces')
        dataset = build_dataset(config, settings, pool=pool)
        stage('training on TAC-CA data')
        last = settings.dagger_rounds == 0
        weights, report = train(dataset, settings, on_epoch, deployed_rmse=last)
        rounds = [round_summary(report)]
        for round_index in range(settings.dagger_rounds):
            path = work_dir / f'dagger_{round_index}.npz'
            save_arrays(weights, path)
            stage(f'DAgger round {round_index + 1}: TAC-GRU runs on the training traces')
            dataset = merge(dataset, build_dataset(config, settings, predictor='gru',
                                                   gru_model=str(path), pool=pool))
            stage(f'DAgger round {round_index + 1}: training on {len(dataset.targets)} '
                  'samples')
            last = round_index == settings.dagger_rounds - 1
            weights, report = train(dataset, settings, on_epoch, deployed_rmse=last)
            rounds.append(round_summary(report))
    report['dagger_rounds'] = settings.dagger_rounds
    report['rounds'] = rounds
    return weights, report


def round_summary(report: dict[str, Any]) -> dict[str, Any]:
    """What the model card keeps of one training round (the last round's curve is kept
    whole; ``validation_rmse_gru`` is PyTorch's for the intermediate rounds)."""
    return {'samples_train': report['samples_train'], 'best_epoch': report['best_epoch'],
            'epochs_run': len(report['curve']),
            'validation_rmse_gru': report['validation_rmse_gru']}


def save_arrays(weights: GruWeights, path: Path) -> None:
    """Write the weights as an ``.npz`` (the format :func:`~.predictors.gru.load_weights`
    reads)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open('wb') as handle:
        np.savez(handle, **{f.name: getattr(weights, f.name)
                            for f in dataclasses.fields(weights)})


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    """Root mean square of a - b over every element."""
    return float(math.sqrt(np.mean(np.square(a - b))))


def train(dataset: Dataset, settings: TrainingSettings,
          on_epoch: Callable[[int, int], None] | None = None, *, deployed_rmse: bool = True
          ) -> tuple[GruWeights, dict[str, Any]]:
    """Train the GRU (seeded, deterministic, one CPU thread); return weights and a report.

    The report's ``validation_rmse_gru`` is the deployed numpy forward pass's (one sample at
    a time, as the planner runs it) if ``deployed_rmse``, else PyTorch's batched one (the
    best epoch's, cheaper: for the intermediate DAgger rounds).
    """
    import torch

    torch.manual_seed(settings.seed)
    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(1)
    generator = torch.Generator().manual_seed(settings.seed)
    train_mask = ~dataset.validation
    mean = dataset.inputs[train_mask].reshape(-1, len(FEATURES)).mean(axis=0)
    std = dataset.inputs[train_mask].reshape(-1, len(FEATURES)).std(axis=0)
    std = np.where(std > 1e-9, std, 1.0)

    def tensor(a: np.ndarray) -> Any:
        return torch.tensor(a, dtype=torch.float64)

    x_train = tensor((dataset.inputs[train_mask] - mean) / std)
    y_train = tensor(dataset.targets[train_mask])
    x_val = tensor((dataset.inputs[~train_mask] - mean) / std)
    y_val = dataset.targets[~train_mask]
    horizon = dataset.targets.shape[1]
    gru: Any = torch.nn.GRU(len(FEATURES), settings.hidden, batch_first=True).double()
    head: Any = torch.nn.Linear(settings.hidden, horizon).double()
    params = list(gru.parameters()) + list(head.parameters())
    optimiser = torch.optim.Adam(params, lr=settings.learning_rate)

    def forward(x: Any) -> Any:
        _, h = gru(x)
        return head(h[-1])

    curve: list[dict[str, float]] = []
    best: tuple[float, int, GruWeights] | None = None
    for epoch in range(settings.epochs):
        order = torch.randperm(len(x_train), generator=generator)
        losses = []
        for start in range(0, len(order), settings.batch_size):
            idx = order[start:start + settings.batch_size]
            optimiser.zero_grad()
            loss = torch.mean((forward(x_train[idx]) - y_train[idx]) ** 2)
            loss.backward()  # type: ignore[no-untyped-call]
            optimiser.step()
            losses.append(loss.item())
        with torch.no_grad():
            val_pred = forward(x_val).numpy()
        curve.append({'epoch': epoch + 1, 'train_mse': float(np.mean(losses)),
                      'validation_rmse': rmse(val_pred, y_val)})
        if best is None or curve[-1]['validation_rmse'] < best[0]:
            # Early stopping: keep the weights of the best validation epoch.
            best = (curve[-1]['validation_rmse'], epoch + 1, GruWeights(
                weight_ih=gru.weight_ih_l0.detach().numpy().copy(),
                weight_hh=gru.weight_hh_l0.detach().numpy().copy(),
                bias_ih=gru.bias_ih_l0.detach().numpy().copy(),
                bias_hh=gru.bias_hh_l0.detach().numpy().copy(),
                out_weight=head.weight.detach().numpy().copy(),
                out_bias=head.bias.detach().numpy().copy(),
                feature_mean=mean, feature_std=std, history_steps=settings.history_steps,
                dt_s=dataset.dt_s))
        if on_epoch is not None:
            on_epoch(epoch + 1, settings.epochs)
        if settings.patience and epoch + 1 - best[1] >= settings.patience:
            break  # the best epoch is kept either way; later ones only cost time
    assert best is not None
    weights = best[2]
    validation_rmse = best[0]
    if deployed_rmse:
        numpy_val = np.array([gru_forward(weights, x) for x in x_val.numpy()])
        validation_rmse = rmse(numpy_val, y_val)
    report = {
        'samples_train': int(train_mask.sum()), 'samples_validation': int((~train_mask).sum()),
        'validation_rmse_gru': validation_rmse,
        'validation_rmse_ca': rmse(dataset.ca_predictions[~train_mask], y_val),
        'best_epoch': best[1], 'curve': curve,
    }
    return weights, report


def save_model(weights: GruWeights, report: dict[str, Any], settings: TrainingSettings,
               out: Path) -> None:
    """Write the ``.npz`` weights, a JSON model card and a loss-curve PNG beside it: the
    three replace what was there together, once all are written (``output_files``)."""
    numerics = numerics_report()
    card = {
        'model': 'one-layer GRU + linear read-out (Ozkan & Ma, eqs. 6-7)',
        'features': list(FEATURES), 'history_steps': weights.history_steps,
        'hidden': weights.hidden, 'horizon_steps': weights.horizon_steps, 'dt_s': weights.dt_s,
        'data': {'traces': list(settings.traces), 'alphas': list(settings.alphas),
                 'runs': 'in-process TAC-CA closed loops with the shipped config/trust_av.yaml, '
                         f'then {settings.dagger_rounds} DAgger round(s): TAC-GRU closed loops '
                         'with the model so far, on the same training traces',
                 'split': f'last {settings.validation_fraction:.0%} of every trace '
                          '(contiguous) is validation'},
        'settings': dataclasses.asdict(settings),
        'results': {k: v for k, v in report.items() if k != 'curve'},
        'trained': datetime.datetime.now(datetime.UTC).date().isoformat(),
        'numerics_fingerprint': numerics['fingerprint'],
        'numerics': numerics['live'],
        'reproduce': 'trust-av train-gru',
    }
    with replacing(out, out.with_suffix('.json'), out.with_suffix('.png')) as (npz, json_, png):
        save_arrays(weights, npz)
        json_.write_text(json.dumps(card, indent=2) + '\n')
        plot_curve(report['curve'], report['validation_rmse_ca'], png)


def plot_curve(curve: list[dict[str, float]], ca_rmse: float, path: Path) -> None:
    """Train MSE and validation RMSE per epoch, with the CA baseline."""
    from trust_av.study.plots import pyplot

    plt = pyplot()

    epochs = [c['epoch'] for c in curve]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(epochs, [math.sqrt(c['train_mse']) for c in curve], label='train RMSE')
    ax.plot(epochs, [c['validation_rmse'] for c in curve], label='validation RMSE')
    ax.axhline(ca_rmse, color='grey', linestyle='--', label='CA on validation')
    ax.set_xlabel('epoch')
    ax.set_ylabel('RMSE of the predicted plan (m/s²)')
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title('GRU plan estimator training')
    fig.tight_layout()
    fig.savefig(path, dpi=110)  # a temporary file of save_model's
    plt.close(fig)
