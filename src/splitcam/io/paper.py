"""The paper's protocol in names and numbers (model.md §7), importable without torch: the one
home of the noise levels it scores and the patterns it compares, which the CLI's defaults, the
design objective, training's pattern mix and the reports read."""

from __future__ import annotations

__all__ = ["PAPER_PATTERNS", "PAPER_SIGMAS", "TABLE1_PATTERNS"]

#: Gaussian noise levels (8-bit units) of the paper's tables.
PAPER_SIGMAS = (0.0, 5.0, 10.0, 15.0, 20.0)
#: The splitter patterns of the paper's Table 1.
TABLE1_PATTERNS = ("A", "B", "C", "D", "E")
#: The patterns the paper compares: Table 1's and the Bayer filter.
PAPER_PATTERNS = (*TABLE1_PATTERNS, "bayer")
