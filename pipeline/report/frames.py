"""pandas frames of results that print as the command line shows them.

Apart from :mod:`debist.api`, which reads them only when a script asks, so that the command
line starts without pandas.

References
----------
pandas, "Subclassing pandas data structures" (``_constructor``),
https://pandas.pydata.org/docs/development/extending.html.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pandas as pd

__all__ = ["NrmseTable"]


class NrmseTable(pd.DataFrame):
    """The NRMSE table of a run: a DataFrame that prints whole, as ``debist run`` shows it.

    ``print(result.nrmse)`` gives every row and column with NRMSE to two decimals [%] and
    RMS to four significant digits; anything derived from it (a selection, a copy) is a
    plain :class:`pandas.DataFrame`.
    """

    @property
    def _constructor(self):
        return pd.DataFrame

    def __repr__(self) -> str:
        formats: dict[str, Callable[[Any], str]] = {
            c: "{:.2f}".format for c in self.columns if str(c).endswith("[%]")
        }
        formats["RMS(q)"] = "{:.4g}".format
        # NaN: not predicted by that model (NARX: q only) or not finished (see status)
        return self.to_string(index=False, formatters=formats, na_rep="n/a")
