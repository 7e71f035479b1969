"""Every file format slamrel reads or writes, one module per format (one reader each)."""
