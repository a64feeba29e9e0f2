"""The cluster detector."""
