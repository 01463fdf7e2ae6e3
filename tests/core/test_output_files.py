"""Output files are written whole or not at all: a failure or a stop while writing leaves
the file that was there before, byte for byte, and no temporary file (a real full disk:
a 200 kB tmpfs, skipped where mounting is not allowed)."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from preceding_traffic.bags import write_trace_bag
from preceding_traffic.errors import PrecedingTrafficError
from trust_av.study import gru_training
from trust_av_common.output_files import OutputFileError, replacing, write_text
from trust_av_planner.predictors.gru import MODELS_DIR, load_weights

BIG = 'x' * 400_000             # larger than the small disk


def test_a_set_of_files_replaces_the_old_set_with_their_permissions(tmp_path: Path) -> None:
    old = tmp_path / 'a.txt'
    old.write_text('old')
    old.chmod(0o640)
    new = tmp_path / 'sub' / 'b.png'
    with replacing(old, new) as (a, b):
        assert a.parent == tmp_path and a.suffix == '.txt' and b.suffix == '.png'
        assert old.read_text() == 'old'                  # nothing replaced while writing
        a.write_text('new a')
        b.write_text('new b')
    assert old.read_text() == 'new a' and new.read_text() == 'new b'
    assert stat.S_IMODE(old.stat().st_mode) == 0o640     # kept, not mkstemp's 0600
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(new.stat().st_mode) == 0o666 & ~umask
    assert sorted(p.name for p in tmp_path.rglob('*')) == ['a.txt', 'b.png', 'sub']


@pytest.mark.parametrize('failure', [KeyboardInterrupt, ValueError])
def test_a_stop_or_error_while_writing_keeps_every_old_file(tmp_path: Path,
                                                            failure: type) -> None:
    first, second = tmp_path / 'model.npz', tmp_path / 'model.json'
    first.write_bytes(b'old weights')
    second.write_text('old card')
    with pytest.raises(failure), replacing(first, second) as (a, _b):
        a.write_bytes(b'new weights')
        raise failure('stopped between the two files')
    assert first.read_bytes() == b'old weights' and second.read_text() == 'old card'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['model.json', 'model.npz']


def test_a_full_disk_is_one_line_and_keeps_the_old_file(small_disk: Path) -> None:
    out = small_disk / 'table.csv'
    out.write_text('old table')
    with pytest.raises(OutputFileError) as error:
        write_text(out, BIG)
    assert str(error.value) == f'{out}: cannot write (No space left on device)'
    assert out.read_text() == 'old table' and [p.name for p in small_disk.iterdir()] == [
        'table.csv']


def test_a_trained_model_on_a_full_disk_keeps_the_shipped_one(small_disk: Path) -> None:
    """The model, its card and its curve replace the old three together or not at all."""
    shipped = MODELS_DIR / 'gru_plan_estimator.npz'
    out = small_disk / 'gru.npz'
    old = {out: b'old weights', out.with_suffix('.json'): b'old card',
           out.with_suffix('.png'): b'old curve'}
    for path, content in old.items():
        path.write_bytes(content)
    (small_disk / 'filler').write_bytes(b'\0' * 172_000)  # ~20 kB left: weights fit, curve not
    report = {'curve': [{'epoch': 1, 'train_mse': 0.04, 'validation_rmse': 0.2}],
              'validation_rmse_ca': 0.3}
    with pytest.raises(OutputFileError, match='No space left on device'):
        gru_training.save_model(load_weights(shipped, 3), report,
                                gru_training.TrainingSettings(), out)
    assert {path: path.read_bytes() for path in old} == old
    assert sorted(p.name for p in small_disk.iterdir()) == ['filler', 'gru.json', 'gru.npz',
                                                            'gru.png']


def test_simulate_out_on_a_full_disk(small_disk: Path) -> None:
    out = small_disk / 'run.csv'
    out.write_text('old run')
    (small_disk / 'filler').write_bytes(b'\0' * 190_000)
    done = subprocess.run([sys.executable, '-m', 'trust_av.cli', 'simulate', '--trace',
                           'us06', '--no-progress', '--out', str(out)], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 2
    assert done.stderr == (f'trust-av simulate: error: {out}: cannot write (No space left '
                           'on device)\n')
    assert out.read_text() == 'old run'
    assert sorted(p.name for p in small_disk.iterdir()) == ['filler', 'run.csv']


def test_a_bag_stopped_half_way_leaves_nothing(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """rosbags' Writer closes a shorter bag that looks finished; the bag is only renamed
    into place once written."""
    from preceding_traffic import bags

    real = bags.odometry_messages

    def stopped_after_three(*args: object) -> object:
        for index, item in enumerate(real(*args)):  # type: ignore[arg-type]
            if index == 3:
                raise KeyboardInterrupt
            yield item

    monkeypatch.setattr(bags, 'odometry_messages', stopped_after_three)
    bag = tmp_path / 'commute'
    with pytest.raises(KeyboardInterrupt):
        write_trace_bag(np.arange(10.0), np.full(10, 3.0), bag, '/lead/odom')
    assert list(tmp_path.iterdir()) == []


def test_a_bag_on_a_full_disk_is_one_line_and_leaves_nothing(small_disk: Path) -> None:
    bag = small_disk / 'commute'
    with pytest.raises(PrecedingTrafficError) as error:
        write_trace_bag(np.arange(20_000.0), np.full(20_000, 3.0), bag, '/lead/odom')
    assert str(error.value) == f'{bag}: cannot write bag (No space left on device)'
    assert list(small_disk.iterdir()) == []


def test_a_link_is_refused_and_a_special_file_written_in_place(tmp_path: Path) -> None:
    """A link would redirect the write to what it names (a link planted in a shared
    directory): refused, nothing written; renaming over ``/dev/stdout`` or a FIFO would
    replace the device, not write to it."""
    import threading

    real = tmp_path / 'results' / 'table.csv'
    real.parent.mkdir()
    real.write_text('old')
    link = tmp_path / 'latest.csv'
    link.symlink_to(real)
    dangling = tmp_path / 'dangling.csv'
    dangling.symlink_to(tmp_path / 'results' / 'new.csv')
    for path in (link, dangling):
        with pytest.raises(OutputFileError) as error:
            write_text(path, 'new')
        assert str(error.value).startswith(f'{path}: a symbolic link (to {tmp_path}')
        assert 'refusing to write through it' in str(error.value)
    with pytest.raises(OutputFileError, match='symbolic link'), replacing(tmp_path / 'a', link):
        pytest.fail('the block runs only when no path is a link')
    assert link.is_symlink() and real.read_text() == 'old'
    assert sorted(p.name for p in real.parent.iterdir()) == ['table.csv']
    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)
    received: list[str] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_text()))
    reader.start()
    write_text(fifo, 'through the pipe')
    reader.join(timeout=30)
    assert received == ['through the pipe'] and stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ['dangling.csv', 'latest.csv', 'pipe',
                                                         'results']


def test_json_to_stdout_through_a_pipe(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, '-c', 'from pathlib import Path\n'
         'from trust_av_common.output_files import write_text\n'
         "write_text(Path('/dev/stdout'), '{}')"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout == '{}' and os.path.islink('/dev/stdout')
