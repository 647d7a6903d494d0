"""A bag directory's own files: NAME/metadata.yaml and NAME/NAME_0.mcap. A bag is replaced,
nothing else in its directory."""

from __future__ import annotations

from pathlib import Path

METADATA_FILE = "metadata.yaml"


def bag_files(directory: Path) -> tuple[str, str]:
    """The names of the files this project writes in a bag directory: metadata.yaml, NAME_0.mcap."""
    return METADATA_FILE, f"{Path(directory).name}_0.mcap"


def foreign_files(directory: Path) -> list[str]:
    """What a directory holds besides a bag's own files (a bag is replaced, nothing else)."""
    return sorted(p.name for p in Path(directory).iterdir() if p.name not in bag_files(directory))


def remove_bag(directory: Path) -> None:
    """Remove a bag's own files, then the directory if that left it empty."""
    for name in bag_files(directory):
        (Path(directory) / name).unlink(missing_ok=True)
    try:
        Path(directory).rmdir()
    except OSError:  # missing, or it holds something else
        pass
