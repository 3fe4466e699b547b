"""Inverse model: measured data only. Never imports `terrain` or reads truth files."""
