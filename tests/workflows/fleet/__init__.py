"""Tests of calibctl.workflows.fleet."""
