"""The companion's offline tools: replay, report, landing report, MCAP and ULog export, the pre-flight doctor, the
height map of a photograph pair, and the warm command server."""
