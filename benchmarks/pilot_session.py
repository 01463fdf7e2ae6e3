"""A pilot session through the real page, as a researcher's first pilot runs it: ``trust-av
drive`` with the shipped drive file (its conditions, rating period and follower), a practice
drive and every condition driven in Debian's headless chromium by the synthetic participant
(benchmarks/synthetic_participant.py), who reads every start screen for ``--start-wait-s``
before pressing Start (a deliberately slow start), rates (every prompt, or on the continuous
scale) and answers the questionnaire.

    python benchmarks/pilot_session.py [--drive-s 120] [--practice-s 60] [--start-wait-s 30]
                                       [--out benchmarks/results_pilot.json]

Then it reads what a pilot report would quote and checks it against what the drive allows:

- per drive, the monitor's last trust in model units (the bag) against its ceiling for the
  drive's own time, ``trust_growth_rate * driven_s`` (trust counted before the Start press
  exceeds it: the start screen here lasts longer than the growth allows);
- ``summary.csv``'s ``final_monitor_trust`` and the recorded ratings on [0, 1], and
  ``comparison.csv``'s RMSE of every model on that scale (an RMSE above 1 cannot come from
  two values on [0, 1]) with its best lag.

Prints the figures and the checks, writes them with the load average and the date; exit 0
when every check holds, 1 otherwise. Nothing in the suite runs it (minutes of wall time).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))


def settings_file(folder: Path, drive_s: float, practice_s: float) -> Path:
    """The shipped drive file with the pilot's drive lengths and any free port."""
    shipped = REPO / 'config' / 'drive.yaml'
    data = yaml.safe_load(shipped.read_text())
    values = data['/**/drive']['ros__parameters']
    values.update(drive_duration_s=drive_s, practice_duration_s=practice_s, port=0)
    path = folder / 'drive.yaml'
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def drive_session(settings: Path, study: Path, start_wait_s: float) -> dict[str, Any]:
    """The whole session through the page; what the participant did and the command said."""
    from playwright.sync_api import sync_playwright
    from synthetic_participant import CHROMIUM, CHROMIUM_ARGS, Participant, drive_once

    process = subprocess.Popen(
        [sys.executable, '-m', 'trust_av.cli', 'drive', '--study', str(study),
         '--participant', 'PILOT', '--drive-file', str(settings)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, 'PYTHONUNBUFFERED': '1'})
    assert process.stdout is not None
    first = process.stdout.readline()
    url = re.search(r'open (http://\S+)', first)
    if url is None:
        process.terminate()
        raise SystemExit(f'pilot_session: trust-av drive printed no URL: {first.strip()}')
    lines: list[str] = []               # read as it comes: a full pipe would stop the drive
    reader = threading.Thread(target=lambda: lines.extend(process.stdout or ()), daemon=True)
    reader.start()
    who = Participant()
    phases = []
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={'width': 800, 'height': 680})
        page.goto(url.group(1))
        drives = yaml.safe_load(settings.read_text())['/**/drive']['ros__parameters']
        for _ in range(1 + len(drives['condition_names'])):   # the practice, each condition
            page.wait_for_selector('#start:not([hidden])', timeout=900_000)
            print(f'start screen of {page.text_content("#title")!r}: read for '
                  f'{start_wait_s:g} s', flush=True)
            time.sleep(start_wait_s)           # the participant reads the instructions
            phases.append(drive_once(page, who, rating=60, until_s=900.0))
        page.wait_for_function("window.drive.phase === 'finished'", timeout=120_000)
        browser.close()
    process.wait(timeout=300)
    reader.join(timeout=30)
    output = ''.join(lines)
    if process.returncode != 0:
        raise SystemExit(f'pilot_session: trust-av drive exit {process.returncode}:\n{output}')
    return {'ratings_given': len(who.ratings), 'questionnaires': who.questionnaires,
            'phases': phases, 'output': output}


def check(study: Path) -> tuple[dict[str, Any], list[str]]:
    """The figures a pilot report quotes, and every check that failed."""
    from trust_av.drive.bag_data import read_drive
    from trust_av.system.config import load_run_config

    growth = load_run_config().trust.trust_growth_rate
    folder = study / 'PILOT'
    session = json.loads((folder / 'session.json').read_text())
    failed: list[str] = []
    drives = []
    for record in session['drives']:
        drive = read_drive(study / record['bag'])
        trust = drive.series.monitor_trust
        finite = trust[trust == trust]
        driven_s = float(drive.metadata['trust_av.drive.driven_s'])
        last = float(finite[-1]) if len(finite) else float('nan')
        ceiling = growth * driven_s
        figures = {'condition': record['condition'], 'status': record['status'],
                   'driven_s': round(driven_s, 2), 'monitor_trust_last': round(last, 4),
                   'ceiling': round(ceiling, 4), 'ratings': [round(float(r), 3)
                                                           for r in drive.ratings]}
        drives.append(figures)
        if not last <= ceiling + 1e-9:
            failed.append(f"{record['condition']}: the monitor's trust {last:.3f} is above its "
                          f'ceiling {ceiling:.3f} for {driven_s:.1f} s of driving')
        if any(not 0.0 <= float(r) <= 1.0 for r in drive.ratings):
            failed.append(f"{record['condition']}: a rating off [0, 1]: {figures['ratings']}")
    with (folder / 'summary.csv').open(newline='') as table:
        summary = list(csv.DictReader(table))
    for row in summary:
        value = float(row['final_monitor_trust'])
        if not 0.0 <= value <= 1.0:
            failed.append(f"summary.csv: final_monitor_trust {value} of {row['condition']} "
                          'is off [0, 1]')
    with (folder / 'comparison.csv').open(newline='') as table:
        comparison = list(csv.DictReader(table))
    for row in comparison:
        if row['rmse'] and float(row['rmse']) > 1.0:
            failed.append(f"comparison.csv: {row['model']} RMSE {row['rmse']} on "
                          f"{row['condition']}: above 1, two scales compared")
    return {'drives': drives, 'summary': summary, 'comparison': comparison}, failed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--drive-s', type=float, default=120.0, help='each drive, s')
    parser.add_argument('--practice-s', type=float, default=60.0, help='the practice, s')
    parser.add_argument('--start-wait-s', type=float, default=30.0,
                        help='how long the participant reads each start screen, s')
    parser.add_argument('--out', type=Path, default=HERE / 'results_pilot.json')
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        study = Path(tmp) / 'study'
        settings = settings_file(Path(tmp), args.drive_s, args.practice_s)
        done = drive_session(settings, study, args.start_wait_s)
        figures, failed = check(study)
    print(done['output'])
    for drive in figures['drives']:
        print(f"{drive['condition']:>12}: {drive['status']}, {drive['driven_s']:.1f} s driven, "
              f"monitor trust {drive['monitor_trust_last']:.3f} (ceiling "
              f"{drive['ceiling']:.3f}), ratings {drive['ratings']}")
    for line in failed:
        print(f'FAILED: {line}')
    print('every check holds' if not failed else f'{len(failed)} checks failed')
    result = {'date': datetime.datetime.now(datetime.UTC).isoformat(timespec='seconds'),
              'cores': os.cpu_count(), 'load_average_1min': [round(load_before, 2),
                                                            round(os.getloadavg()[0], 2)],
              'drive_s': args.drive_s, 'practice_s': args.practice_s,
              'start_wait_s': args.start_wait_s, 'ratings_given': done['ratings_given'],
              'questionnaires': done['questionnaires'], **figures, 'failed': failed}
    args.out.write_text(json.dumps(result, indent=1) + '\n')
    print(f'written: {args.out}')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
