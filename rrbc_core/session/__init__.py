"""The interactive session behind the browser app (`explorer`): everything the app shows is computed and tested
here."""
