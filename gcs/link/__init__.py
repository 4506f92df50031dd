"""Links to the vehicle: MAVLink connections and the link budget."""
