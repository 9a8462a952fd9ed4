"""The paper's experiments as runnable presets, and the demo."""
