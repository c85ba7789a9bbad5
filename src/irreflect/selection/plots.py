from ..plots.selection import plot_pareto, plot_points, plot_selection  # noqa: F401  shim until cli/ merge (selection/cli.py imports these from here)
