"""The coverage model's verdict (issue 29)."""
