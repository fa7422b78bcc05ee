"""Progress bars for long CLI runs (tqdm, to stderr)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from tqdm import tqdm

__all__ = ["progress_bar"]


class _Bar(tqdm):
    def update_to(self, done: int) -> None:
        """Set the absolute count of finished items."""
        self.update(done - self.n)


@contextlib.contextmanager
def progress_bar(total: int, *, desc: str, unit: str = "it", quiet: bool = False
                 ) -> Iterator[_Bar]:
    """A tqdm bar with ``update_to(done)``; silent when ``quiet``."""
    # disable=None: tqdm switches itself off when stderr is not a terminal (CI logs).
    with _Bar(total=total, desc=desc, unit=unit, disable=True if quiet else None,
              mininterval=0.5,
              leave=False) as bar:
        yield bar
