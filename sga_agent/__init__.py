"""The LLM-driven bilevel search (SGA) and its command-line interface.

The outer level asks a large language model to propose physics code (for example constitutive
laws) from the prompt templates shipped as ``sga_agent.prompts``; the inner level fits the
continuous parameters of each proposal by differentiable simulation through :mod:`bridges` and
:mod:`taichi_mpm`, and the scores feed back into the next round of proposals. It is being built;
only :mod:`sga_agent.resources` exists so far.
"""
