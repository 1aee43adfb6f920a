"""``python -m compgen`` and the ``compgen`` / ``compgen-cli`` commands: the command line,
with BLAS held to one thread before numpy loads."""

import os

# compgen's matrices are tall and thin (3n × p, p ≤ ~130): a second BLAS thread adds only
# hand-over cost, and OpenBLAS's idle workers spin while numpy loads (~0.07 s of CPU in
# every command, half of `import numpy`; benchmarks/startup.py). Set before numpy is first
# imported, for each BLAS numpy may be built on; the library itself leaves BLAS alone.
BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def main() -> None:
    os.environ.update(dict.fromkeys(BLAS_THREADS, "1"))
    from .commands.cli import main as command_line

    command_line()


if __name__ == "__main__":
    main()
