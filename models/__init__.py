"""The packaged models: the trunk's MJCF and the built-in scene files.

This folder is the package `hybrid.models` of an installed hybrid (pyproject.toml
maps it); `hybrid.scenefile.packaged_model` finds its files."""
