"""The LLM-driven bilevel search (SGA) and its command-line interface.

The outer level asks a large language model to propose physics code (for example constitutive
laws) from the prompt templates shipped as ``sga_agent.prompts``; the inner level fits the
continuous parameters of each proposal by differentiable simulation through :mod:`bridges` and
:mod:`taichi_mpm`, and the scores feed back into the next round of proposals.

So far it holds the task contract (:mod:`sga_agent.task`) and the plugin registry
(:mod:`sga_agent.registry`), the sandbox that evaluates untrusted candidates in a limited worker
process (:mod:`sga_agent.sandbox`, :mod:`sga_agent.worker`), the prompt templates
(:mod:`sga_agent.resources`) and the ``sga-agent`` command line with its ``tasks`` and
``evaluate`` commands (:mod:`sga_agent.cli`); the search loop itself is being built.
"""
