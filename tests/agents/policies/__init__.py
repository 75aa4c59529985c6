"""Tests of the policies room (agents/policies): the safe policy format, loading trained policies,
the pickle opt-in and the conversion from SB3's files."""
