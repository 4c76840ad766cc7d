"""Scene files, where data lives, and the files a run writes."""
