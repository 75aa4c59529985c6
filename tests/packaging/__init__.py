"""The installed package: the wheel's contents, the import names and the console scripts."""
