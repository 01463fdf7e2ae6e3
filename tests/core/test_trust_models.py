"""The shipped trust models beyond the contract: their equations and special cases."""

from __future__ import annotations

import dataclasses
import random
import subprocess
import sys
from pathlib import Path

import pytest
from support.paths import REPO

from trust_av.study.tables import BOUND_HEADER
from trust_monitor.model_interface import make_trust_model
from trust_monitor.paper_trust import TrustConfig, trust_step
from trust_monitor.shipped_models import BetaState, OptimoConfig, OptimoModel

BASE = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                   trust_initial=0.0)


def scores(n: int, seed: int) -> list[float]:
    rng = random.Random(seed)
    return [rng.choice((rng.uniform(0.0, 0.2), rng.uniform(0.2, 1.0))) for _ in range(n)]


@pytest.mark.parametrize('seed', range(5))
def test_paper_is_a_special_case_of_optimo(seed: int) -> None:
    """w_b = 0, w_p = delta, w_d = 0, sigma = 0 and P_thre: OPTIMo's mean is eqs. (10)-(11)
    while it stays inside [0, 1] (here: delta 0.001 /s, from T(0) = 0.5, 200 steps)."""
    base = dataclasses.replace(BASE, trust_growth_rate=0.001, trust_initial=0.5)
    special = OptimoModel(base, OptimoConfig(optimo_bias_rate_per_s=0.0,
                                             optimo_performance_rate_per_s=0.001,
                                             optimo_change_gain=0.0, optimo_noise_std=0.0,
                                             optimo_initial_trust=0.5,
                                             optimo_performance_threshold=0.8))
    state, trust = special.initial_state(), base.trust_initial
    for score in scores(200, seed):
        state = special.step(state, score, 1.0)
        trust = trust_step(trust, score, base)
        assert special.trust(state) == trust
        assert special.variance(state) == 0.0
    # ... and not for another w_d: the special case is a real restriction
    other = OptimoModel(base, dataclasses.replace(special.params, optimo_change_gain=0.5))
    state = other.initial_state()
    for score in (0.0, 0.5):
        state = other.step(state, score, 1.0)
    assert other.trust(state) != trust_step(trust_step(0.5, 0.0, base), 0.5, base)


def test_optimo_trust_stays_in_the_unit_interval() -> None:
    """OPTIMo's trust is bounded: good performance saturates at 1, failures floor at 0, and
    a reported trust cannot push it outside."""
    model = OptimoModel(BASE, OptimoConfig(optimo_performance_rate_per_s=0.1))
    state = model.step(model.initial_state(), 0.0, 60.0)        # P = 1 for a minute
    assert model.trust(state) == 1.0
    state = model.step(state, 1.0, 600.0)                       # P < P_thre for 10 min
    assert model.trust(state) == 0.0
    noisy = OptimoModel(BASE, OptimoConfig(optimo_noise_std=0.2))
    state = noisy.step(noisy.initial_state(), 0.0, 1.0)
    assert noisy.trust(noisy.observe(state, 5.0, 0.01)) == 1.0


def test_optimo_variance_grows_and_a_report_shrinks_it() -> None:
    model = OptimoModel(BASE, OptimoConfig(optimo_noise_std=0.2))
    state = model.step(model.initial_state(), 0.5, 4.0)
    assert state.variance == pytest.approx(0.2 ** 2 * 4.0)
    after = model.observe(state, 0.3, noise_variance=state.variance)
    assert after.variance == pytest.approx(state.variance / 2)
    assert after.mean == pytest.approx((state.mean + 0.3) / 2)


def test_beta_bernoulli_counts_binary_episodes() -> None:
    """Guo & Yang: an episode adds w_s to alpha when it succeeds (mean P >= threshold) and
    w_f to beta when it fails, however far from the threshold P is."""
    model = make_trust_model(dataclasses.replace(BASE, trust_model='beta_bernoulli'),
                             {'beta_bernoulli_episode_s': 3.0,
                              'beta_bernoulli_failure_weight': 2.0,
                              'beta_bernoulli_success_weight': 0.5})
    state = model.initial_state()
    for _ in range(2):
        state = model.step(state, 0.3, 1.0)
    assert (state.alpha, state.beta) == (1.0, 1.0)  # the episode is not over
    state = model.step(state, 0.3, 1.0)              # P = 0.709 < 0.8: a failure
    assert state == BetaState(1.0, 3.0)
    assert model.step(model.initial_state(), 0.9, 3.0) == state    # a worse failure: same
    state = model.step(state, 0.1, 3.0)              # P = 0.900: a success
    assert (state.alpha, state.beta) == (1.5, 3.0)
    assert model.trust(state) == pytest.approx(1.5 / 4.5)
    a, b = state.alpha, state.beta
    assert model.variance(state) == pytest.approx(a * b / ((a + b) ** 2 * (a + b + 1)))


def test_beta_bernoulli_forgets_towards_its_prior() -> None:
    model = make_trust_model(dataclasses.replace(BASE, trust_model='beta_bernoulli'),
                             {'beta_bernoulli_forgetting': 0.5})
    state = model.initial_state()
    for _ in range(3):                                # three successes: 1 + 1/2 + 1/4 + 1
        state = model.step(state, 0.0, 1.0)
    assert (state.alpha, state.beta) == pytest.approx((1.0 + 1.75, 1.0))
    for _ in range(60):                               # a minute of failures
        state = model.step(state, 1.0, 1.0)
    assert state.alpha == pytest.approx(1.0) and state.beta == pytest.approx(3.0)


def test_beta_bernoulli_step_across_an_episode_end_is_split() -> None:
    model = make_trust_model(dataclasses.replace(BASE, trust_model='beta_bernoulli'))
    one = model.step(model.step(model.initial_state(), 0.1, 0.5), 0.9, 1.0)
    two = model.step(model.step(model.step(model.initial_state(), 0.1, 0.5), 0.9, 0.5), 0.9,
                     0.5)
    assert (one.alpha, one.beta) == pytest.approx((two.alpha, two.beta))
    # the first episode: half at P(0.1) = 0.90, half at P(0.9) = 0.28: mean 0.59, a failure
    assert (one.alpha, one.beta) == (1.0, 2.0)



def test_beta_bernoulli_in_the_loop_binds_on_its_beta_mean() -> None:
    """In the closed loop (US06, 30 steps) with T_min 0.6, above Beta(1, 1)'s 0.5, the
    reported trust is a Beta mean (2/3 after the first, successful episode, not T units)
    and the NMPC's trust constraint binds in the first steps, where it depends on the Beta
    counts, not only on T. That this run is also what the node graph records (the planner
    mirrors the monitor's model in lock-step) is the graph half of the trust-model contract
    for ``beta_bernoulli`` (tests/graph/test_trust_model_contract_graph.py, the same T_min:
    the initial trust + 0.1)."""
    from preceding_traffic.sources import load_trace
    from preceding_traffic.traces import truncate
    from trust_av.system.closed_loop import simulate
    from trust_av.system.config import load_run_config
    config = load_run_config((), {'/**': {'trust_model': 'beta_bernoulli'},
                                  'planner': {'alpha': 0.5, 'predictor': 'ca', 'trust_min': 0.6}})
    model = config.trust_model()
    assert model.trust(model.initial_state()) + 0.1 == pytest.approx(0.6)   # the contract's
    trace = truncate(load_trace('us06', config.planner.dt_s, config.trace), 30)
    records = simulate(config, trace).records
    binding = [r.explicability_max for r in records if r.explicability_max < 1.0]
    assert len(binding) >= 3, 'the trust constraint must bind for this test to mean anything'
    assert records[0].trust == pytest.approx(2 / 3, rel=0.01)

def test_every_shipped_model_maps_to_the_common_scale() -> None:
    """paper/asymmetric: T(0) -> 0.5, T(0) +- delta 600 s -> 1 / 0; the others are on
    [0, 1] already."""
    from trust_monitor.model_interface import common_trust
    paper = make_trust_model(BASE)
    assert common_trust(paper, 0.0) == 0.5
    assert common_trust(paper, 60.0) == 1.0 and common_trust(paper, -30.0) == 0.25
    assert common_trust(paper, 1e9) == 1.0
    for name in ('beta_bernoulli', 'optimo'):
        model = make_trust_model(dataclasses.replace(BASE, trust_model=name))
        assert common_trust(model, model.initial_state()) == 0.5


def test_asymmetric_loses_twice_what_it_gains() -> None:
    model = make_trust_model(dataclasses.replace(BASE, trust_model='asymmetric'))
    low = 0.9  # P = 1 - tanh(0.9) < 0.8: a loss
    loss = model.step(0.0, low, 1.0)
    assert loss == pytest.approx(2.0 * trust_step(0.0, low, BASE))
    assert model.step(0.0, 0.01, 1.0) == trust_step(0.0, 0.01, BASE)  # gains as the paper


@pytest.mark.parametrize(('model', 'has_bound'), [('paper', True), ('asymmetric', False)])
def test_tables_give_the_paper_bound_only_for_the_paper_model(model: str, has_bound: bool,
                                                              tmp_path: Path) -> None:
    """The least-final-trust column is derived from eqs. (9)-(11): another model's tables
    leave it out (and do not crash)."""
    params = tmp_path / 'model.yaml'
    params.write_text(f'/**:\n  ros__parameters:\n    trust_model: {model}\n')
    out = tmp_path / 'results'
    proc = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'reproduce',
                           '--traces', 'us06', '--predictors', 'ca', '--max-steps', '20',
                           '--params-file', str(params), '--results-dir', str(out),
                           '--workers', '1', '--no-progress'],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    header = (out / 'table_III_tac_ca_us06.csv').read_text().splitlines()[0]
    assert (BOUND_HEADER in header) is has_bound
    assert header.startswith('alpha,final trust,mean E')


@pytest.mark.parametrize('values', [{'trust_model': 'asymmetric'},
                                    {'asymmetric_loss_ratio': 3.0}])
def test_planner_and_monitor_run_one_model(values: dict[str, object]) -> None:
    """The model and its parameters have one value per graph: a planner section that
    differs from the monitor's is refused, naming both nodes."""
    from trust_av.system.config import load_run_config
    from trust_av_common.params import ParamsError
    name = next(iter(values))
    with pytest.raises(ParamsError, match=rf'{name} is .* for planner but .* for '
                                          r'trust_monitor: the planner and the monitor must '
                                          r'run the same trust model'):
        load_run_config((), {'planner': values})
    config = load_run_config((), {'/**': values})  # set once, in /**: accepted
    assert getattr(config.trust, name, None) == values[name] or \
        dict(config.trust_model_params)[name] == values[name]


def test_bound_benchmark_smoke(tmp_path: Path) -> None:
    """benchmarks/bench_trust_models.py runs on a few calls and writes every model's figures."""
    import json
    out = tmp_path / 'bench.json'
    script = REPO / 'benchmarks' / 'bench_trust_models.py'
    proc = subprocess.run([sys.executable, str(script), '--calls', '2', '--out', str(out)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    results = json.loads(out.read_text())
    from trust_av_common.registry import names
    from trust_monitor.model_interface import TRUST_MODELS
    assert set(results['models']) == set(names(TRUST_MODELS))
    assert results['models']['paper']['1 Hz']['closed_form'] is True
