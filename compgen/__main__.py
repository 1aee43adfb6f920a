"""``python -m compgen`` and the ``compgen`` / ``compgen-cli`` commands: the command line,
with BLAS held to one thread before numpy loads."""

import contextlib
import os

# compgen's matrices are tall and thin (3n × p, p ≤ ~130): a second BLAS thread adds only
# hand-over cost, and OpenBLAS's idle workers spin while numpy loads (~0.07 s of CPU in
# every command, half of `import numpy`; benchmarks/startup.py). Set before numpy is first
# imported, for each BLAS numpy may be built on; the library itself leaves BLAS alone.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


M_ARENA_MAX = -8         # glibc's mallopt parameter (malloc.h)


def _one_malloc_arena() -> None:
    """glibc gives each thread a heap ("arena") of its own and keeps resident what a thread
    frees there: the memory the model's two workers (``kinematics.in_halves``) free would stay
    in a process's peak (about 100 MiB of diagnose's at 723 000 readings; docs/benchmarks.md).
    MALLOC_ARENA_MAX=1 would do it but is read when the process starts; a C library without
    mallopt (not glibc) is left as it is."""
    import ctypes  # numpy loads it anyway

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).mallopt(M_ARENA_MAX, 1)


def main() -> None:
    os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))
    _one_malloc_arena()
    from .commands.cli import main as command_line

    command_line()


if __name__ == "__main__":
    main()
