"""Pinned floating-point numerics for the GRU training process (docs/GRU.md).

Training the GRU runs closed loops (CasADi, numpy) whose inputs come from the GRU's own
numpy forward pass, then trains in PyTorch. Every library on that path picks some of its
floating-point kernels by CPU when it loads, so the same seed gives other weights on
another CPU. The choices, and how they are fixed for one process (they are read at load
time, so they can only be set in the environment of a fresh process):

* numpy picks a kernel set per instruction-set group (numpy 2.4 dispatches X86_V3,
  X86_V4, AVX512_ICL, AVX512_SPR; ``__cpu_dispatch__``). ``NPY_DISABLE_CPU_FEATURES``
  turns off every group above X86_V3, so an AVX-512 CPU runs the AVX2 kernels (its
  ``exp`` then falls back to glibc's, like an AVX2 CPU's; measured: one ulp apart on
  about 5 % of inputs otherwise).
* numpy's BLAS (OpenBLAS, ``DYNAMIC_ARCH``) picks a kernel per core type
  (``OPENBLAS_CORETYPE``; this AMD EPYC gets ``Haswell``, AVX-512 Intel CPUs
  ``SkylakeX`` or newer): pinned to ``Haswell`` (its kernels need AVX2 and FMA).
* PyTorch's ATen kernels per capability (``ATEN_CPU_CAPABILITY``: default, avx2,
  avx512): pinned to ``avx2``.
* PyTorch's BLAS is MKL (``torch.__config__.show()``: ``BLAS_INFO=mkl``); it picks a
  code branch per CPU. ``MKL_CBWR=AVX2`` is honoured on Intel CPUs only (on others MKL
  uses its automatic branch; Intel's oneMKL developer guide, "Getting Started with
  Conditional Numerical Reproducibility"); ``COMPATIBLE`` (SSE2 code) is the branch
  that holds on Intel and non-Intel CPUs alike, so it is used (measured here: ``AVX2``
  and ``SSE4_2`` give the automatic branch's bits on this AMD CPU, ``COMPATIBLE`` other
  ones, so the setting is taken).
* oneDNN (``ONEDNN_MAX_CPU_ISA``) is capped at AVX2 in case a float32 path reaches it;
  the float64 GRU does not use it.
* Threads: one (``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``;
  the trainer also calls ``torch.set_num_threads(1)``): reductions split by thread
  count otherwise.
* glibc's libm (``exp``, ``log``, ``pow``, ``expm1`` under ``tanh``, ``sin``, ...)
  chooses FMA variants by CPU (ifunc). Every CPU with AVX2 and FMA gets the FMA variant,
  so nothing needs pinning on the supported CPUs; ``GLIBC_TUNABLES`` (which could
  switch them off) is removed from the child's environment. numpy's ``exp`` (float64,
  below AVX-512), Python's ``math.tanh`` in the trust model and CasADi's compiled
  ``std::exp``-style calls all land here.
* CasADi (``sqpmethod`` + ``qrqp``) is built for plain x86-64 and has no CPU dispatch of
  its own on this path (its bundled OpenBLAS is not loaded; ``/proc/PID/maps`` of a
  training run); its libm calls are covered above.

Supported: an x86-64 CPU with numpy's X86_V3 group (AVX2, FMA3, BMI1/2, F16C, LZCNT,
MOVBE; every AVX2 CPU has them). Elsewhere the child still runs single-threaded with the
CPU-independent settings (MKL ``COMPATIBLE``), but the model is not bit-comparable.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

from trust_av.errors import TrustAvAppError
from trust_av.graph import stop_signals
from trust_av_planner.predictors.gru import FEATURES

__all__ = ['CHILD_MARK', 'check_pinned', 'in_pinned_child', 'main', 'numerics_report',
           'run_pinned', 'unsupported_reason']

PINNED_NUMPY_TARGET = 'X86_V3'
"""The highest numpy dispatch group the pinned process may use."""

X86_V3_FEATURES = ('AVX', 'AVX2', 'FMA3', 'F16C', 'BMI', 'BMI2', 'LZCNT', 'MOVBE')
"""The CPU features numpy's X86_V3 group needs (numpy's feature names)."""

CHILD_MARK = 'TRUST_AV_PINNED_NUMERICS'
"""Set in the pinned child's environment (to ``1``, or ``partial`` without AVX2)."""

THREAD_VARIABLES = {'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1',
                    'OPENBLAS_NUM_THREADS': '1', 'MKL_DYNAMIC': 'FALSE'}
PORTABLE_VARIABLES = {'MKL_CBWR': 'COMPATIBLE', 'ONEDNN_MAX_CPU_ISA': 'AVX2'}
AVX2_VARIABLES = {'OPENBLAS_CORETYPE': 'Haswell', 'ATEN_CPU_CAPABILITY': 'avx2'}
REMOVED_VARIABLES = ('NPY_ENABLE_CPU_FEATURES', 'GLIBC_TUNABLES', 'MKL_ENABLE_INSTRUCTIONS',
                     'MKL_DEBUG_CPU_TYPE', 'DNNL_MAX_CPU_ISA', 'OPENBLAS_VERBOSE')
"""User settings that would undo or bypass the pin; dropped from the child's environment."""


def unsupported_reason() -> str | None:
    """Why this machine cannot run the pinned numerics, or None if it can.

    Reads numpy's CPU detection (per feature, which ``NPY_DISABLE_CPU_FEATURES`` does not
    change), so the answer is the hardware's even if the caller's numpy runs unpinned.
    """
    if platform.machine().lower() not in ('x86_64', 'amd64'):
        return f'the CPU is {platform.machine()}, not x86-64'
    missing = [f for f in X86_V3_FEATURES if not __cpu_features__.get(f)]
    if missing:
        return f'the CPU lacks {", ".join(missing)} (x86-64-v3, AVX2 and FMA, is required)'
    return None


def numpy_disabled_targets() -> list[str]:
    """numpy's dispatch groups above :data:`PINNED_NUMPY_TARGET` (to switch off)."""
    targets = list(__cpu_dispatch__)
    if PINNED_NUMPY_TARGET not in targets:
        raise RuntimeError(f'numpy {np.__version__} does not dispatch {PINNED_NUMPY_TARGET} '
                           f'(its groups: {targets}); update pinned_numerics')
    return targets[targets.index(PINNED_NUMPY_TARGET) + 1:]


def pinned_environment(base: Mapping[str, str]) -> dict[str, str]:
    """``base`` with the pinned numerics settings (module docstring) imposed on it."""
    env = {k: v for k, v in base.items() if k not in REMOVED_VARIABLES}
    env.update(THREAD_VARIABLES)
    env.update(PORTABLE_VARIABLES)
    env['NPY_DISABLE_CPU_FEATURES'] = ','.join(numpy_disabled_targets())
    if unsupported_reason() is None:
        env.update(AVX2_VARIABLES)
        env[CHILD_MARK] = '1'
    else:
        for name in AVX2_VARIABLES:
            env.pop(name, None)
        env[CHILD_MARK] = 'partial'
    return env


def run_pinned(args: Sequence[str], extra_env: Mapping[str, str] | None = None,
               **kwargs: Any) -> subprocess.CompletedProcess[str]:
    """Run ``python ARGS`` in a fresh process with the pinned numerics.

    ``extra_env`` is applied *before* the pin (it stands for the caller's own settings,
    which the pin overrides). ``kwargs`` go to :class:`subprocess.Popen`. The child runs in
    its own process group and stops with this process: a stop signal here (Ctrl-C or a
    hang-up at the terminal, which reach only this group, or SIGINT/SIGTERM/SIGHUP sent to
    this process) is passed on to it once, then we wait for it to finish its files and
    return its code (130, 143, 129); if this process dies, the child gets SIGTERM.
    """
    env = pinned_environment({**os.environ, **(extra_env or {})})
    with subprocess.Popen([sys.executable, *args], env=env, text=True, process_group=0,
                          preexec_fn=stop_signals.stop_with_parent, **kwargs) as process:
        try:
            stdout, stderr = process.communicate()
        except KeyboardInterrupt as stop:
            process.send_signal(getattr(stop, 'signum', signal.SIGINT))
            stdout, stderr = process.communicate()
        return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def in_pinned_child() -> bool:
    """True in a process started by :func:`run_pinned`."""
    return CHILD_MARK in os.environ


MKL_BRANCHES = {1: 'OFF', 2: 'AUTO', 3: 'COMPATIBLE'}
"""``mkl_cbwr_get`` results (oneMKL's ``mkl_cbwr.h``: ``MKL_CBWR_BRANCH_OFF`` = 1, the
default) that we can meet here; others are shown as their number."""


def _mkl_branch() -> int:
    """MKL's code branch in this process (``mkl_cbwr_get(MKL_CBWR_BRANCH)``; PyTorch links
    MKL statically and exports it as ``mkl_serv_cbwr_get``), or -1 if unavailable."""
    import ctypes

    import torch

    try:
        lib = ctypes.CDLL(os.path.join(os.path.dirname(torch.__file__), 'lib',
                                       'libtorch_cpu.so'))
        get = lib.mkl_serv_cbwr_get
    except (OSError, AttributeError):
        return -1
    get.restype = ctypes.c_int
    get.argtypes = [ctypes.c_int]
    return int(get(1))  # MKL_CBWR_BRANCH


LIBRARIES = ('numpy', 'libm', 'torch')
"""The libraries whose kernels :func:`numerics_report` hashes."""


def check_libraries(libraries: Sequence[str]) -> None:
    """Raise ``ValueError`` unless ``libraries`` names one or more of :data:`LIBRARIES`."""
    unknown = sorted(set(libraries) - set(LIBRARIES))
    if unknown or not libraries:
        what = f'unknown libraries {unknown}' if unknown else 'no library named'
        raise ValueError(f'{what}; give one or more of {",".join(LIBRARIES)}')


def live_numerics(torch_settings: bool = True) -> dict[str, Any]:
    """What this process's libraries actually chose (a description for the model card);
    without ``torch_settings``, numpy's and libc's only (PyTorch is then not imported)."""
    import ctypes
    import glob

    active = [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]
    openblas = '?'
    libs = glob.glob(os.path.join(os.path.dirname(np.__path__[0]), 'numpy.libs',
                                  'libscipy_openblas64_*.so'))
    if libs:
        corename = ctypes.CDLL(libs[0]).scipy_openblas_get_corename64_
        corename.restype = ctypes.c_char_p
        openblas = corename().decode()
    live: dict[str, Any] = {
        'pinned': os.environ.get(CHILD_MARK, 'no'),
        'numpy': np.__version__, 'numpy_dispatch': active,
        'openblas_core': openblas,
        'libc': ' '.join(platform.libc_ver()),
    }
    if torch_settings:
        import torch

        live.update({
            'mkl_branch': MKL_BRANCHES.get(_mkl_branch(), f'branch {_mkl_branch()}'),
            'torch': torch.__version__,
            'torch_cpu_capability': str(torch.backends.cpu.get_cpu_capability()),
            'threads': torch.get_num_threads()})
    return live


def check_pinned() -> None:
    """Raise :class:`~trust_av.errors.TrustAvAppError` naming the setting if this pinned child's
    libraries did not take the pin (e.g. a library version that ignores the variable)."""
    if os.environ.get(CHILD_MARK) != '1':
        return
    live = live_numerics()
    wanted = {'numpy_dispatch': [PINNED_NUMPY_TARGET], 'openblas_core': 'Haswell',
              'torch_cpu_capability': 'AVX2', 'mkl_branch': 'COMPATIBLE', 'threads': 1}
    for key, value in wanted.items():
        if live[key] != value:
            raise TrustAvAppError(f'pinned numerics not in effect: {key} is {live[key]!r}, '
                               f'expected {value!r}')


def _digest(*arrays: Any) -> str:
    digest = hashlib.sha256()
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()[:16]


def numerics_report(libraries: Sequence[str] = LIBRARIES) -> dict[str, Any]:
    """The bits of the floating-point kernels the training pipeline runs on, per library,
    and what this process's libraries chose (:func:`live_numerics`).

    Kernels: numpy ``exp``/``tanh``, matrix-vector products (OpenBLAS) and reductions; glibc
    libm through Python's ``math`` (``exp``, ``tanh``, ``atanh``, ``log``, ``pow``; the trust
    model and CasADi call the same functions); PyTorch's float64 matrix product (MKL),
    sigmoid/tanh and one GRU forward, backward and update step (ATen). Library versions
    and the live settings are part of the fingerprint, the CPU model is not: in the pinned
    training process (this module) it is the same on every x86-64 CPU with AVX2.

    ``libraries`` (a subset of :data:`LIBRARIES`) limits the kernels, the live settings
    and so the fingerprint to those libraries; without ``'torch'`` PyTorch is not imported
    (about 1.5 CPU-s). The model card holds the whole fingerprint of the pinned training
    process, and the retraining test demands bit equality when its own pinned process
    gives the same one (retraining is bit-for-bit reproducible only with the same
    numerics: the GRU's numpy forward pass feeds the DAgger closed loops, so one ulp of a
    kernel moves the trained model).
    """
    check_libraries(libraries)
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 3.0, 4096)
    matrix = rng.normal(0.0, 1.0, (48, 16))
    kernels = {
        'numpy': _digest(np.exp(x), np.tanh(x), 1.0 / (1.0 + np.exp(-x)), matrix @ x[:16],
                         matrix.T @ x[:48], np.array([x.mean(), x.std()])),
        'libm': _digest(np.array([[math.exp(v), math.tanh(v), math.atanh(math.tanh(v) * 0.999),
                                   math.log(abs(v) + 1e-3), math.pow(abs(v) + 0.5, 1.7)]
                                  for v in x[:1024]])),
    }
    kernels = {name: kernels[name] for name in libraries if name in kernels}
    if 'torch' in libraries:
        kernels['torch'] = _torch_kernels(x, matrix)
    live = live_numerics(torch_settings='torch' in libraries)
    fingerprint = _digest(np.frombuffer(json.dumps([kernels, live], sort_keys=True).encode(),
                                        dtype=np.uint8))
    return {'fingerprint': fingerprint, 'kernels': kernels, 'live': live}


def _torch_kernels(x: np.ndarray, matrix: np.ndarray) -> str:
    """Digest of PyTorch's float64 matrix product, sigmoid/tanh and one GRU forward,
    backward and update step."""
    import torch

    with torch.random.fork_rng():
        torch.manual_seed(0)
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            gru = torch.nn.GRU(len(FEATURES), 16, batch_first=True).double()
            head = torch.nn.Linear(16, 3).double()
            params = list(gru.parameters()) + list(head.parameters())
            inputs = torch.randn(64, 10, len(FEATURES), dtype=torch.float64)
            target = torch.randn(64, 3, dtype=torch.float64)
            loss = torch.mean((head(gru(inputs)[1][-1]) - target) ** 2)
            loss.backward()  # type: ignore[no-untyped-call]
            with torch.no_grad():  # an Adam-like step (torch.optim would import the compiler)
                for p in params:
                    grad = p.grad
                    assert grad is not None
                    p.sub_(3e-3 * grad / (torch.sqrt(grad * grad) + 1e-8))
            a = torch.tensor(matrix)
            return _digest(
                (a.T @ a).numpy(), torch.sigmoid(torch.tensor(x)).numpy(),
                torch.tanh(torch.tensor(x)).numpy(),
                *[p.detach().numpy() for p in params])
        finally:
            torch.set_num_threads(threads)


def main(argv: list[str] | None = None) -> int:
    """``python -m trust_av.study.pinned_numerics [--libraries numpy,libm]``: print
    this process's numerics (fingerprint, its parts, the live settings) as JSON."""
    import argparse

    parser = argparse.ArgumentParser(
        prog='python -m trust_av.study.pinned_numerics',
        description="Print this process's floating-point numerics as JSON: the fingerprint "
                    'the GRU model card stores, the kernel digests per library and the '
                    'settings the libraries chose.')
    parser.add_argument('--libraries', default=','.join(LIBRARIES),
                        help='comma-separated subset of %(default)s (default: all); the '
                             'kernels, settings and fingerprint cover only these')
    args = parser.parse_args(argv)
    libraries = [name for name in args.libraries.split(',') if name]
    try:
        check_libraries(libraries)
    except ValueError as err:
        parser.error(f'--libraries {args.libraries!r}: {err}')
    check_pinned()
    print(json.dumps(numerics_report(libraries), sort_keys=True))
    return 0


if __name__ == '__main__':
    sys.exit(main())
