"""Tests for flrjax.agents.gc_td3, one file per module."""
