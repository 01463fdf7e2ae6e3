"""The example plug-in (examples/trust_av_example_plugin), installed with pip outside the
trust-av sources, is found by every command: simulate, the node graph (its node processes),
the study, and passes the component contract; adding it needed no file under src/."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from support.example_plugin import install_example_plugin
from support.paths import REPO, TESTS

from human_driver_sim.followers import DRIVERS
from trust_av_planner.predictors import PREDICTORS

PLUGIN_TESTS = REPO / 'examples' / 'trust_av_example_plugin' / 'tests'
STEPS = 12


@pytest.fixture(scope='module')
def plugin_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The environment of a user who installed the plug-in (:mod:`example_plugin`)."""
    return install_example_plugin(tmp_path_factory.mktemp('plugin'))


@pytest.fixture(scope='module')
def trace_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp('plugin_trace') / 'ramp.csv'
    path.write_text('time_s,speed_mps\n' + ''.join(
        f'{t},{8.0 + 0.5 * t if t < 10 else 13.0 - 0.4 * (t - 10):.3f}\n'
        for t in range(STEPS + 1)))
    return path


def trust_av(env: dict[str, str], *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, '-m', 'trust_av.cli', *args], env=env,
                          cwd=cwd, capture_output=True, text=True, timeout=300,
                          stdin=subprocess.DEVNULL)


def test_simulate_lists_and_runs_the_plugin(plugin_env: dict[str, str], trace_csv: Path,
                                            tmp_path: Path) -> None:
    helped = trust_av(plugin_env, 'simulate', '--help', cwd=tmp_path)
    assert '{ca,cv,gru,ses}' in helped.stdout.replace('\n', '').replace(' ', '')
    without = trust_av(dict(os.environ), 'simulate', '--trace', str(trace_csv), '--predictor',
                       'ses', '--no-progress', cwd=tmp_path)
    assert without.returncode == 2 and "invalid choice: 'ses'" in without.stderr
    out = tmp_path / 'ses.csv'
    proc = trust_av(plugin_env, 'simulate', '--trace', str(trace_csv), '--predictor', 'ses',
                    '--no-progress', '--out', str(out), cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert 'TAC-SES' in proc.stdout and len(out.read_text().splitlines()) == STEPS + 1
    # its parameter comes from the planner's section, like a shipped component's
    params = tmp_path / 'ses.yaml'
    params.write_text('/**/planner:\n  ros__parameters:\n    predictor: ses\n'
                      '    ses_damping: 0.0\n')
    damped = trust_av(plugin_env, 'simulate', '--trace', str(trace_csv), '--params-file',
                      str(params), '--no-progress', '--out', str(tmp_path / 'd.csv'),
                      cwd=tmp_path)
    assert damped.returncode == 0, damped.stderr
    rows = (tmp_path / 'd.csv').read_text().splitlines()
    header = rows[0].split(',')
    expected = [header.index(f'expected_plan_mps2_{k}') for k in range(3)]
    # phi = 0: the human expects zero acceleration, whatever the AV did
    assert all(float(row.split(',')[i]) == 0.0 for row in rows[1:] for i in expected)


def test_study_runs_the_plugin(plugin_env: dict[str, str], trace_csv: Path,
                              tmp_path: Path) -> None:
    out = tmp_path / 'study'
    proc = trust_av(plugin_env, 'reproduce', '--traces', str(trace_csv), '--predictors',
                    'ses,ca', '--alphas', '0,1', '--max-steps', '6', '--results-dir', str(out),
                    '--workers', '2', '--no-progress', cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = (out / 'all_runs.csv').read_text().splitlines()
    header = rows[0].split(',')
    predictor, damping = header.index('predictor'), header.index('ses_damping')
    ses = [r.split(',') for r in rows[1:] if r.split(',')[predictor] == 'ses']
    assert len(ses) == 2 and all(r[damping] == '0.8' for r in ses)   # its declared default
    table = (out / 'table_IV_max_improvements.csv').read_text()
    assert f'TAC-SES,{trace_csv},' in table


def test_study_cache_keys_on_the_plugins_code(plugin_env: dict[str, str],
                                              tmp_path: Path) -> None:
    """A cached case must not outlive a change of the plug-in's code: its module is part of
    the sweep's code fingerprint."""
    code = ('from trust_av.study import sweep; '
            'print([p.name for p in sweep.plugin_sources()]); print(sweep.code_fingerprint())')
    def run(env: dict[str, str]) -> list[str]:
        proc = subprocess.run([sys.executable, '-c', code], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout.splitlines()
    with_plugin, without = run(plugin_env), run(dict(os.environ))
    # both of its registered modules: the plan estimator and the trust model
    assert with_plugin[0] == "['leaky_trust.py', 'smoothing.py']" and without[0] == '[]'
    assert with_plugin[1] != without[1]


def contract(plugin_env: dict[str, str], tmp_path: Path, modules: tuple[str, ...],
             selection: str, verbosity: str) -> subprocess.CompletedProcess[str]:
    """The selected tests of ``tests/<tier>/<module>`` run with the plug-in installed; they
    pass."""
    proc = subprocess.run([sys.executable, '-m', 'pytest', '-n', '0', verbosity, '-p',
                           'no:cacheprovider', '-k', selection,
                           *(str(TESTS / module) for module in modules)],
                          env=plugin_env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=600, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


@pytest.fixture(scope='module')
def contract_run(plugin_env: dict[str, str], tmp_path_factory: pytest.TempPathFactory) -> str:
    """One pytest session (``-v``) with the plug-in installed, of the repository's contract
    tests selected for its two components (``ses``: tests/graph/test_component_contract.py;
    ``leaky``: tests/core/test_trust_model_contract.py and its graph half), read by the two
    tests below; every selected test passes. Its output."""
    return contract(plugin_env, tmp_path_factory.mktemp('contract'),
                    ('graph/test_component_contract.py', 'core/test_trust_model_contract.py',
                     'graph/test_trust_model_contract_graph.py'),
                    'predictors-ses or (needs and ses) or leaky', '-v').stdout


def passed(stdout: str, module: str) -> set[str]:
    """The tests of ``module`` that a ``-v`` pytest output reports PASSED."""
    return set(re.findall(rf'{re.escape(module)}::(\S+) PASSED', stdout))


def test_plugin_passes_the_component_contract(contract_run: str) -> None:
    """``ses`` passes every rule of tests/graph/test_component_contract.py. Its graph half is
    the node graph running the plug-in: the planner's process loads ``ses`` from the
    installed package, and the graph records what the in-process loop computes with it."""
    assert passed(contract_run, 'test_component_contract.py') == {
        'test_contract[predictors-ses]',
        'test_bad_parameter_is_refused_in_one_line[predictors-ses]',
        'test_the_declared_needs_decide_what_runs_without_the_follower[ses]',
        'test_graph_equals_in_process[predictors-ses]'}, contract_run


def test_plugin_runs_the_shipped_contract_in_its_own_test(plugin_env: dict[str, str],
                                                           tmp_path: Path) -> None:
    """The plug-in's own CI (examples/trust_av_example_plugin/tests/test_contract.py) imports
    the contract from the installed trust-av, as any package outside the repository does
    (its graph half is the same rule the repository's contract tests above run)."""
    proc = subprocess.run([sys.executable, '-m', 'pytest', '-n', '0', '-q', '-p',
                           'no:cacheprovider', '-k', 'not graph',
                           str(PLUGIN_TESTS / 'test_contract.py')],
                          env=plugin_env, cwd=tmp_path, capture_output=True, text=True,
                          timeout=600, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0 and '2 passed' in proc.stdout, proc.stdout + proc.stderr


def test_plugin_trust_model_passes_the_trust_model_contract(contract_run: str) -> None:
    """``leaky``, registered by the installed package only, is held to every rule of
    tests/core/test_trust_model_contract.py and its graph half (the node graph == in-process
    run)."""
    assert 'test_graph_equals_in_process[leaky]' in passed(
        contract_run, 'test_trust_model_contract_graph.py'), contract_run
    assert 'test_contract[leaky]' in passed(contract_run, 'test_trust_model_contract.py'), \
        contract_run


def test_no_file_under_src_names_the_plugin() -> None:
    for path in (REPO / 'src').rglob('*'):
        if path.is_file() and path.suffix in {'.py', '.cfg', '.xml', '.yaml', '.toml'}:
            text = path.read_text()
            assert 'trust_av_example_plugin' not in text and 'ses_damping' not in text, path


def test_tutorial_includes_the_example_files() -> None:
    """The tutorial's code blocks are the package's real files (MkDocs snippets), so they
    cannot drift from what the tests install and run."""
    import re

    text = (REPO / 'docs' / 'tutorials' / 'write-a-plugin.md').read_text()
    included = re.findall(r'^--8<-- "([^"]+)"$', text, flags=re.MULTILINE)
    assert set(included) == {
        'examples/trust_av_example_plugin/pyproject.toml',
        'examples/trust_av_example_plugin/trust_av_example_plugin/smoothing.py',
        'examples/trust_av_example_plugin/tests/test_contract.py'}
    for path in included:
        assert (REPO / path).is_file(), path


def test_components_reference_lists_every_shipped_component() -> None:
    from trust_av_common import registry

    text = (REPO / 'docs' / 'reference' / 'components.md').read_text()
    for group in (PREDICTORS, DRIVERS):
        for component in registry.components(group):
            if component.factory.__module__.split('.')[0] in ('trust_av_planner',
                                                              'human_driver_sim'):
                assert f'| `{component.name}` |' in text, component.name
