"""The trial manager's result files in out_dir: trials.csv as each trial ends, and at the end
final_weights.npy and summary.json. Each is written to a temporary file, then renamed: a full
disk keeps the last whole file, and the problem comes back as one line."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from ..files import describe_write_error, write_atomically, write_text_atomically
from ..graph.fields import summary_json, trials_csv


class TrialFiles:
    def __init__(self, out_dir: str, seed: int, log_error: Callable[[str], None]):
        self.out, self.seed, self.log_error = Path(out_dir) if out_dir else None, seed, log_error

    def trials(self, results: list) -> str | None:
        """trials.csv of `results` [(trial, initial angle, steps, end reason)]; the problem or
        None."""
        return self._save(lambda: self._write_trials(results))

    def results(self, results: list, final_weights, ticks: int, wall_s: float,
                exit_reason: str, exit_status: int) -> str | None:
        def write() -> None:
            self._write_trials(results)
            if final_weights is not None:
                def save_weights(temporary: Path) -> None:
                    with open(temporary, "wb") as f:
                        np.save(f, final_weights)
                write_atomically(self.out / "final_weights.npy", save_weights)
            write_text_atomically(self.out / "summary.json", summary_json(
                self.seed, [r[2] for r in results], ticks, wall_s, exit_reason, exit_status))
        return self._save(write)

    def _write_trials(self, results: list) -> None:
        write_text_atomically(self.out / "trials.csv",
                              trials_csv([self.seed, *result] for result in results))

    def _save(self, write: Callable[[], None]) -> str | None:
        if self.out is None:
            return None
        try:
            write()
        except OSError as error:
            self.log_error(describe_write_error(error))
            return describe_write_error(error)
        return None


def progress_line(trial: int, trials: int, steps: list[int], rate: float) -> str:
    """The line printed as trial `trial` (from 1) ends."""
    return f"trial {trial:4d}/{trials}  steps {steps[-1]:6d}  mean {np.mean(steps):8.1f}  " \
           f"{rate:7.0f} ticks/s"
