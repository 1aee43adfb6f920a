"""``python -m compgen`` and the ``compgen`` / ``compgen-cli`` commands: the command line,
with BLAS held to one thread before numpy loads."""

import contextlib
import os

# compgen's matrices are tall and thin (3n × p, p ≤ ~130): a second BLAS thread adds only
# hand-over cost, and OpenBLAS's idle workers spin while numpy loads (~0.07 s of CPU in
# every command, half of `import numpy`; benchmarks/startup.py). Set before numpy is first
# imported, for each BLAS numpy may be built on; the library itself leaves BLAS alone.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


# glibc's mallopt parameters (malloc.h) and what compgen sets them to
M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD, M_ARENA_MAX = -1, -2, -3, -8
MALLOC = {M_ARENA_MAX: 1, M_MMAP_THRESHOLD: 1 << 30, M_TRIM_THRESHOLD: (1 << 31) - 1, M_TOP_PAD: 64 << 20}


def _malloc_settings() -> None:
    """How glibc's malloc serves a dense session's arrays (each of 20–200 MB at 723 000
    readings), made and dropped dozens of times in a command:

    - one heap ("arena") for all threads: glibc gives each thread its own and keeps resident
      what a thread frees there, so the memory the model's two workers
      (``kinematics.in_halves``) free would stay in a process's peak;
    - from that heap, kept when freed: by default an array beyond the mmap threshold is fresh
      memory from the kernel each time and goes back to it when freed, and on a virtual
      machine every fresh page is a fault (about 2 ms a MiB here: a second or more of
      diagnose's system time at that size).

    The MALLOC_*_ variables would do it but are read when the process starts; a C library
    without mallopt (not glibc) is left as it is."""
    import ctypes  # numpy loads it anyway

    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None)
        for parameter, value in MALLOC.items():
            libc.mallopt(parameter, value)


def main() -> None:
    os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))
    _malloc_settings()
    from .commands.cli import main as command_line

    command_line()


if __name__ == "__main__":
    main()
