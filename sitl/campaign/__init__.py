"""Campaigns: many seeded landing missions (conditions x strategies x runs), their metrics, statistics and report."""
