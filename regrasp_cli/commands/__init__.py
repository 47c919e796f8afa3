"""The command layer: what the click commands call.  Modules here parse, call the
library, and print (rich); nothing below this package imports it."""
