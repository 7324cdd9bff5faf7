"""Prompt templates for the SGA agent, importable as ``sga_agent.prompts`` (data only)."""
