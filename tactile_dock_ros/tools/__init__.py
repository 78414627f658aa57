"""Command-line tools: benchmarks, replay and plotting."""
