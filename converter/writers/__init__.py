"""Writers: the 2D data a stage built (Sheet, Fat2dSheet) -> bytes. One module per output; converter.outputs
registers each one with its output kind."""
