"""Presets resolved into stage configs, and the one runner that strings the stages together."""
