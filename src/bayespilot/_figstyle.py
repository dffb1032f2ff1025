"""How the package writes its figures: resolution, formats, vector text.

Light on purpose (no matplotlib, no numba): the command line reads it at start-up.
"""

from __future__ import annotations

#: Resolution of the figures the package writes, dots per inch: the commands' (``bayespilot
#: plot``, ``demo``) and the diagnosis reports'.  200 dpi is for the screen and for drafts, not
#: for print: for a paper write a vector format (PDF, SVG: :data:`PLOT_FORMATS`), or a PNG at
#: 300 dpi or more (journals ask 300 for halftones, 600 for line art).
PLOT_DPI = 200
#: Formats a figure can be written in (matplotlib picks the writer by the suffix).
PLOT_FORMATS = ("png", "pdf", "svg")
#: How a vector figure keeps its text: TrueType fonts in a PDF (Type 3 fonts, matplotlib's
#: default, fail the font checks of AIAA's and IEEE's PDF submission), text as text in an
#: SVG; save with ``matplotlib.rc_context(VECTOR_TEXT)``.
VECTOR_TEXT = {"pdf.fonttype": 42, "ps.fonttype": 42, "svg.fonttype": "none"}
#: What makes an SVG the same each time the same figure is saved: its ids (of clip paths,
#: ...) hashed with this fixed salt, not a random one (matplotlib's ``svg.hashsalt``); the
#: dates are left out by :func:`save_figure`'s ``metadata``.
REPRODUCIBLE = {"svg.hashsalt": "bayespilot"}


def figure_options(title, formats, dpi) -> dict:
    """The figure options a command or a batch takes, checked before anything runs:
    ``title`` True or False (TypeError otherwise), ``formats`` one or more of
    :data:`PLOT_FORMATS` (a name, or a sequence of them, each once in the order given) and
    ``dpi`` None or a whole number >= 1 (ValueError otherwise).  Returns ``{"title": bool,
    "formats": tuple, "dpi": int | None}``."""
    import numbers

    # (numpy's bool is a bool, as plots._title_text takes it: numpy 1 names its type "bool_",
    # numpy 2 "bool"; checked by name, this module imports no numpy)
    if not (isinstance(title, bool) or (type(title).__module__ == "numpy"
                                        and type(title).__name__ in ("bool", "bool_"))):
        raise TypeError(f"title must be True or False, got {title!r}")
    if isinstance(formats, str):
        formats = (formats,)
    try:
        formats = tuple(dict.fromkeys(formats))
    except TypeError:
        raise ValueError(f"formats must be names among {', '.join(PLOT_FORMATS)}, got "
                         f"{formats!r}") from None
    bad = [f for f in formats if f not in PLOT_FORMATS]
    if bad or not formats:
        raise ValueError(f"formats must be one or more of {', '.join(PLOT_FORMATS)}, got "
                         f"{bad[0] if bad else 'none'}")
    if dpi is not None and (isinstance(dpi, bool) or not isinstance(dpi, numbers.Integral)
                            or dpi < 1):
        raise ValueError(f"dpi must be a whole number >= 1, got {dpi!r}")
    return {"title": bool(title), "formats": formats, "dpi": None if dpi is None else int(dpi)}


def save_figure(fig, path, dpi: int = PLOT_DPI) -> None:
    """Write ``fig`` to ``path`` (format from its suffix) at ``dpi``, a vector format with
    its text kept (:data:`VECTOR_TEXT`); the figure stays open (the caller closes it).

    The file is written atomically (:func:`bayespilot._files.replacing`: a temporary file
    beside it, then renamed), so an interrupt or a full disk leaves the old file or the new
    one, never a truncated one.  A ``path`` without a suffix gets matplotlib's default
    format's, as ``savefig`` gives it; a file object is written to directly.

    The same figure gives the same bytes (:data:`REPRODUCIBLE`, :func:`_metadata`): an SVG
    without a date and with ids from a fixed salt, a PDF without a creation date, so that a
    command run twice writes identical files (for version control and checksums).  A PNG is
    written as matplotlib writes it (it has no date).
    """
    import os

    import matplotlib

    from ._files import replacing

    if not isinstance(path, (str, os.PathLike)):  # a file object: nothing to replace
        with matplotlib.rc_context({**VECTOR_TEXT, **REPRODUCIBLE}):
            fmt = matplotlib.rcParams["savefig.format"]  # (what savefig writes to it)
            fig.savefig(path, dpi=dpi, **_metadata(fmt))
        return
    path = os.fspath(path)
    fmt = os.path.splitext(path)[1][1:]
    if not fmt:  # as savefig does: the default format, its suffix appended
        fmt = matplotlib.rcParams["savefig.format"]
        path = f"{path.rstrip('.')}.{fmt}"
    # format= given: savefig would take it from the temporary file's suffix (".tmp")
    with matplotlib.rc_context({**VECTOR_TEXT, **REPRODUCIBLE}), replacing(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=fmt, **_metadata(fmt))


def _metadata(fmt: str) -> dict:
    """``savefig``'s keyword that leaves the date out of a figure of format ``fmt`` and names
    the release that drew it: an SVG's ``Date`` (its ``dc:date``) and a PDF's
    ``CreationDate`` set to None, which matplotlib leaves out (a PNG has no date), and the
    PNG's ``Software``, the PDF's and SVG's ``Creator``, "bayespilot X, Matplotlib Y" (they
    named Matplotlib alone: a figure could not be traced to the code that drew it)."""
    import matplotlib

    from . import __version__

    fmt = str(fmt).lower()
    made = f"bayespilot {__version__}, Matplotlib {matplotlib.__version__}"
    meta = {"svg": {"Date": None, "Creator": made}, "pdf": {"CreationDate": None,
                                                            "Creator": made},
            "png": {"Software": made}}.get(fmt)
    return {} if meta is None else {"metadata": meta}
