"""The flight log: its schema and one checked reader, the recorder that writes it, and the views of its records
(timeline, Foxglove messages) that the live flight and the offline tools share."""
