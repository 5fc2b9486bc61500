"""One module per book page: its ``Config`` (smoke-scale defaults), ``run_*(cfg)`` per table
or experiment, ``compare_*`` against the thesis and ``plot_*``. Notebooks and the CLI import
these; nothing in the method packages does."""
