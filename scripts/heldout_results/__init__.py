"""The library behind ``scripts/results.py``: held-out entries in, ``docs/results.md`` out.

:mod:`heldout_results.entries` reads and checks the committed entries;
:mod:`heldout_results.page` renders the page.
"""
