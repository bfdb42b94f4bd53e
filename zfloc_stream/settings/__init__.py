"""The settings sections, one module per part of the package; zfloc_stream.settings.loading composes
them into Settings and loads them (see loading.py)."""
