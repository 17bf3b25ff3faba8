"""Descriptions of mechanisms: the files and formats a mechanism is read from."""
