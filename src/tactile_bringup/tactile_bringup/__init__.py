"""Configuration, launch, MCAP recorder/player, exploration runner and benchmarks."""
