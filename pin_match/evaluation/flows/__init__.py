"""The flows that compose ``core`` and ``pages``: ``report``, ``bench``, ``compare``, ``carry``, ``demo``.

Each writes a folder (a report, a bench, a comparison, a demo with its ``index.html``, from
``index_page``) from score tables and frame-sets; nothing below imports them.
"""
