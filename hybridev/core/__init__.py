"""Bottom layer: shared warnings and errors, argument checks, file I/O and progress bars.

Imports nothing else of hybridev, so every layer may use it.
"""
