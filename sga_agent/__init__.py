"""The LLM-driven bilevel search (SGA) and its command-line interface.

The outer level asks a proposer (a language model through litellm, or a task's LLM-free
evolutionary proposer) for hypotheses from the prompt templates shipped as
``sga_agent.prompts``; the inner level fits each proposal's continuous parameters by
differentiable simulation inside a task plugin, and the scores feed back into the next prompt.

Modules, one job each: :mod:`.task` (the task contract), :mod:`.registry` (plugins through
entry points), :mod:`.prompting` and :mod:`.parsing` (prompts in, answers out, static checks),
:mod:`.proposers` (litellm backbone), :mod:`.sandbox`, :mod:`.capture_server`,
:mod:`.fit_worker` and :mod:`.isolation` (each candidate captured in a confined process, scored
by a trusted fit worker), :mod:`.fingerprint` (identical code is evaluated once),
:mod:`.heap`, :mod:`.search` (Algorithm 1), :mod:`.config` (settings and presets),
:mod:`.run_store` (the run folder), :mod:`.runner` and :mod:`.cli` (``sga-agent``).
"""
