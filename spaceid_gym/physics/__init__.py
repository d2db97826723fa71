"""Pure functions of arrays: rigid-body inertia, fuel removal, the free-floating momentum map."""
