//! lamina-gcode: G-code for multi-material and mixing printers.
