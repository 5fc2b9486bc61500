"""One module per chapter notebook: its ``Config`` (defaults = the smoke scale), ``run_*(cfg) ->
DataFrame`` per table or experiment, ``compare_*`` beside the thesis (through
:func:`thesis_lib.book.compare_with_paper`) and ``plot_*``. The methods they call live in the
method packages (:mod:`thesis_lib.dtw`, :mod:`thesis_lib.rl`, :mod:`thesis_lib.defender`,
:mod:`thesis_lib.clfd`, :mod:`thesis_lib.mdlt`, ...); only notebooks and the CLI import this package.
"""
