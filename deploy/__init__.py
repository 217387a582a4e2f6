"""Starting whole teams: the local launcher (``btrack sim``) and deployment files."""
