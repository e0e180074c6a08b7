"""The shoot-time terminal UI (Textual)."""
