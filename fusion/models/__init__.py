"""Motion and measurement models beyond the core's built-ins, loadable by import path.

Pure like fusion.core (numpy only, no I/O): `helix` holds the helix models of the reference
scenarios; `loader` imports and validates a user's model given as "package.module:Name".
"""
