"""Readers and writers of hexatherm's files (contracts in the project's formats spec)."""
