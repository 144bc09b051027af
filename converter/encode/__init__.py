"""Writer-neutral encoding of a Sheet's motion: numbers and error budgets, never markup.

budget (a tolerance split once into its parts), keys (keyframes on sampled values), freeknots (keyframes with
free values), groups (rigid motion factored into group transforms), order (drawing order), overlap (which
paths may touch on screen), parallel (compiled loops on a few threads). Writers turn what these return into
their own syntax.
"""
