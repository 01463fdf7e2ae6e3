"""scripts/compare_trust_models.py: every registered model, offline and in closed loop."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

from support.graph import STEPS
from support.paths import REPO

from trust_av_common.registry import names
from trust_monitor.model_interface import TRUST_MODELS

SCRIPT = REPO / 'scripts' / 'compare_trust_models.py'


def test_every_model_is_scored_offline_and_in_closed_loop(tmp_path: Path) -> None:
    proc = subprocess.run([sys.executable, str(SCRIPT), '--max-steps', '15', '--out',
                           str(tmp_path)], capture_output=True, text=True, timeout=600,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with (tmp_path / 'trust_models.csv').open() as handle:
        rows = list(csv.DictReader(handle))
    models = names(TRUST_MODELS)
    assert sorted((r['mode'], r['trust_model']) for r in rows) == sorted(
        (mode, m) for mode in ('offline', 'closed loop') for m in models)
    by = {(r['mode'], r['trust_model']): r for r in rows}
    # The recorded run is the paper model's: offline paper is that run's own trust.
    assert by['offline', 'paper']['final_trust'] == by['closed loop', 'paper']['final_trust']
    assert by['offline', 'optimo']['final_variance'] not in ('', 'None')
    assert by['offline', 'paper']['final_variance'] == ''
    assert 0.0 < float(by['offline', 'beta_bernoulli']['final_trust']) < 1.0
    assert (tmp_path / 'trust_models.png').stat().st_size > 10_000


def test_offline_on_a_graph_recording(us06_graph_run: tuple[Path, str],
                                      tmp_path: Path) -> None:
    """--bag: the models are scored on a trust-av run recording (the suite's shared US06
    run: TAC-CA, alpha 0.5, STEPS steps); the paper model replayed over the bag's E gives
    the trust the graph's monitor recorded (= the in-process run of as many steps)."""
    bag, _ = us06_graph_run
    out = tmp_path / 'out'
    proc = subprocess.run([sys.executable, str(SCRIPT), '--max-steps', str(STEPS), '--bag',
                           str(bag), '--out', str(out)], capture_output=True, text=True,
                          timeout=600, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    with (out / 'trust_models.csv').open() as handle:
        by = {(r['mode'], r['trust_model']): r for r in csv.DictReader(handle)}
    from trust_av.graph.bag_records import records_from_bag
    recorded = records_from_bag(bag)
    assert len(recorded) == STEPS
    assert float(by['offline', 'paper']['final_trust']) == recorded[-1].trust
    assert by['offline', 'paper']['final_trust'] == by['closed loop', 'paper']['final_trust']
