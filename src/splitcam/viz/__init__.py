"""Every figure splitcam draws. Each function creates its own :class:`matplotlib.figure.Figure`
(never pyplot), so library code never switches the user's backend or leaks open figures."""
