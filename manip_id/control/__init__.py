"""Control that uses the parameters: adaptive laws and the closed-loop simulation."""
