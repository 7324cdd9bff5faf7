"""Scientific task plugins for the SGA bilevel search.

Each task (a simulation setup, its learnable physics and its loss) is a plugin that the agent
discovers through the ``sga_agent.tasks`` entry-point group, so tasks shipped here and tasks from
other distributions are found the same way. It is being built; no task is registered yet.
"""
