"""The cuespin command, batch runs, experiments and charts."""
