"""The metrics core: frame labels, metrics, sweeps, intervals, stop policies, sigma and its tuning, ``EvalContext``.

Tables and frame-sets in, numbers out; it draws no picture and writes no page. ``pages`` and
``flows`` build on it; it imports neither.
"""
