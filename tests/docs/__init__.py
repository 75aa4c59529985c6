"""The README and the documentation pages: length, links, and agreement with the code."""
