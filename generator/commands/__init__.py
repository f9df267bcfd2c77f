"""The `gyrogen` commands, one module per family; cli.py assembles them."""
