"""The book's pages, one module per notebook.

Each holds its ``Config`` (defaults = the smoke scale), ``run_*(cfg) -> DataFrame`` per table or
experiment, ``compare_*`` beside the thesis's numbers (through
:func:`thesis_lib.book.compare_with_paper`) and ``plot_*``. The notebooks and the CLI import them;
nothing in the method packages does.
"""
