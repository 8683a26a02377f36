"""Exports of endocal's results to where robotics people use them, one module per format.

- :mod:`endocal.export.c`: a fitted model's streaming compensator as C99 source
  (``endocal export c``), for a real-time loop outside Python;
- :mod:`endocal.export.mcap`: a run folder as an MCAP file with JSON-Schema channels
  (``endocal export mcap``), for Foxglove and PlotJuggler.

Nothing heavy is imported here: each format imports what it needs when called.
"""
