"""Hardware package: filled by later issues (see docs/ and ../shared/DESIGN.md)."""
