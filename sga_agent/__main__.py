"""``python -m sga_agent``: the ``sga-agent`` command line."""

from sga_agent.cli import run

if __name__ == "__main__":
    run()
