"""Registers every subcommand on the root app (kept apart so importing the app stays cheap)."""
