// A small POV-Ray scene whose noise comes from a jittered area light sampled sparsely and
// from focal blur: the kind of colour-only image temc denoises as a post-pass.
#version 3.7;
global_settings { assumed_gamma 1.0 }
// Sample counts: pass Declare=Samples=N and Declare=Lights=N for a reference render.
#ifndef (Samples) #declare Samples = 6; #end
#ifndef (Lights) #declare Lights = 3; #end

camera {
  location <0, 1.6, -6>
  look_at <0, 0.8, 0>
  angle 45
  aperture 0.35            // focal blur
  blur_samples Samples     // few samples: noisy
  focal_point <0, 0.8, 0>
}

light_source {
  <3, 6, -3> color rgb <1.0, 0.95, 0.85> * 1.4
  area_light <2, 0, 0>, <0, 0, 2>, Lights, Lights
  jitter                   // random positions per sample: soft, noisy shadows
}

sky_sphere { pigment { color rgb <0.25, 0.3, 0.4> } }

plane { y, 0 pigment { checker color rgb 0.8 color rgb 0.2 scale 0.7 } finish { diffuse 0.8 } }
sphere { <-1.1, 0.9, 0.5>, 0.9 pigment { color rgb <0.8, 0.15, 0.1> } finish { specular 0.4 roughness 0.02 } }
box { <0.4, 0, -0.6>, <1.8, 1.4, 0.8> rotate y*25 pigment { color rgb <0.2, 0.4, 0.8> } }
sphere { <0.2, 0.45, -1.6>, 0.45 pigment { color rgb <0.9, 0.8, 0.3> } }
