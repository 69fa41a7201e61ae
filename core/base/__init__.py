"""Foundations every layer uses: errors, decisions, progress and cancel, atomic writes, output folders, limits."""
