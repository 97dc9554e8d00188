"""Figures of the paper, drawn with matplotlib from the pipeline's own tables.

One module per figure so that a change to one figure's style reruns only that figure's rule;
:mod:`dtwin.figures._style` holds the shared look and the deterministic, atomic saver.
"""
