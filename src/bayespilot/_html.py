"""How the result types show in a notebook (Jupyter, VS Code): their readable summary.

Their ``repr`` is one line (a fit's held every GA history); a notebook cell that ends with
a result shows ``_repr_html_`` instead: the account ``print(result.summary())`` gives, as
preformatted text (its tables are aligned by spaces).
"""

from __future__ import annotations

import html


class SummaryHTML:
    """A base class (no fields, no state): ``_repr_html_`` is the class's ``summary()`` text,
    escaped, in a ``<pre>`` block.  A class whose readable account is its ``str`` (the
    posterior, a campaign's summary) sets :attr:`_html_text` to ``"__str__"``."""

    #: The method whose text a notebook shows.
    _html_text = "summary"

    def _repr_html_(self) -> str:
        """The summary in a notebook, escaped (a source path with ``<`` or ``&``)."""
        return f"<pre>{html.escape(getattr(self, self._html_text)())}</pre>"
