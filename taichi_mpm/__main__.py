"""``python -m taichi_mpm``: the ``taichi-mpm`` command line."""

from taichi_mpm.cli import main

if __name__ == "__main__":
    main(prog_name="taichi-mpm")
