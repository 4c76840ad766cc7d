"""The validation studies of the FOM, ROM and PROM (SPEC §11, `make validate`): cases and their
cached runner, the studies, and the figures and report written from their JSON files."""
