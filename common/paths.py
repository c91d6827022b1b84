"""Where the checkout is: one definition, so a module moved deeper cannot miscount its depth."""

from pathlib import Path

# common/ sits directly under the project root.
PROJECT_ROOT = str(Path(__file__).resolve().parents[1])
