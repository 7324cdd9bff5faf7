"""``python -m sga_agent``: the ``sga-agent`` command line."""

from sga_agent.cli import main

if __name__ == "__main__":
    main(prog_name="sga-agent")
